//! Bundles edited as a careful forger would: a file changed and its size
//! and hash fixed up in the manifest, so that only a reader's own checks
//! stand between the edit and the reader. One file, included by the
//! end-to-end tests here and the process-level tests beside the binary.

use std::path::{Path, PathBuf};

/// Record the new size and SHA-256 of `file` in `bundle`'s manifest.
pub fn rehash(bundle: &Path, file: &str) {
    let path = bundle.join("manifest.json");
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let (bytes, sha) = relevo_core::bundle::sha256_file(&bundle.join(file)).unwrap();
    for artifact in manifest["artifacts"].as_object_mut().unwrap().values_mut() {
        if artifact["file"] == file {
            artifact["bytes"] = bytes.into();
            artifact["sha256"] = sha.clone().into();
        }
    }
    std::fs::write(&path, serde_json::to_string_pretty(&manifest).unwrap()).unwrap();
}

/// A copy of `bundle` named `name` beside it, with `edit` applied to
/// `file`'s bytes and the manifest fixed up.
pub fn forged(bundle: &Path, name: &str, file: &str, edit: &dyn Fn(&mut Vec<u8>)) -> PathBuf {
    let copy = bundle.with_file_name(name);
    let status = std::process::Command::new("cp")
        .args(["-a".as_ref(), bundle.as_os_str(), copy.as_os_str()])
        .status()
        .unwrap();
    assert!(status.success());
    let mut bytes = std::fs::read(copy.join(file)).unwrap();
    edit(&mut bytes);
    std::fs::write(copy.join(file), bytes).unwrap();
    rehash(&copy, file);
    copy
}
