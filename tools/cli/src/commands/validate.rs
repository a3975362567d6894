//! `relevo validate`: check a bundle's files, hashes, shapes and invariants.

use anyhow::{bail, Result};
use clap::Args;
use relevo_core::bundle::Bundle;
use relevo_core::validation::validate;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ValidateArgs {
    /// The bundle to check.
    pub bundle: PathBuf,
}

pub fn run(a: ValidateArgs) -> Result<()> {
    let path = &a.bundle;
    let problems = if relevo_core::bundle::format_of(path).as_deref()
        == Some(relevo_core::bundle::PYRAMID_FORMAT)
    {
        let pyramid = relevo_core::pyramid::Pyramid::open(path)?;
        relevo_core::validation::validate_pyramid(&pyramid, true)
    } else {
        validate(&Bundle::open(path)?)
    };
    if problems.is_empty() {
        println!("{}: valid", path.display());
        Ok(())
    } else {
        for p in &problems {
            eprintln!("{}: {p}", path.display());
        }
        bail!("{}: {} problem(s)", path.display(), problems.len())
    }
}
