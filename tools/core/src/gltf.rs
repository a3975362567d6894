//! Binary glTF 2.0 (`.glb`): arrays laid into one binary chunk as buffer
//! views with their accessors, and the container around the JSON document
//! (glTF 2.0 specification, §4.4 "GLB file format").
//!
//! ```
//! use relevo_core::gltf::{Glb, ARRAY_BUFFER};
//! let mut glb = Glb::default();
//! let positions = glb.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]], Some(ARRAY_BUFFER));
//! let doc = serde_json::json!({
//!     "asset": {"version": "2.0"},
//!     "meshes": [{"primitives": [{"attributes": {"POSITION": positions}}]}],
//!     "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0,
//! });
//! let bytes = glb.finish(doc).unwrap();
//! assert_eq!(&bytes[..4], b"glTF");
//! assert_eq!(bytes.len() % 4, 0);
//! ```

use crate::{Error, Result};
use serde_json::{json, Value};

/// Buffer view targets: vertex attributes and indices.
pub const ARRAY_BUFFER: u32 = 34962;
pub const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// Accessor component types.
pub const UNSIGNED_BYTE: u32 = 5121;
pub const UNSIGNED_INT: u32 = 5125;
pub const FLOAT: u32 = 5126;

/// A glb being assembled: its binary chunk, buffer views and accessors.
#[derive(Default)]
pub struct Glb {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Glb {
    /// `bytes` as a new buffer view, 8-byte aligned (any component, 64-bit
    /// metadata values included, starts aligned), with `target` when the
    /// view holds vertex attributes or indices: its index.
    pub fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        self.align();
        let mut view =
            json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(view);
        self.views.len() - 1
    }

    /// An accessor of `count` elements of `kind` (`"SCALAR"`, `"VEC3"`…)
    /// and `component_type` over new view of `bytes`; `extra` is merged into
    /// it (`min`, `max`, `normalized`). Its index.
    pub fn accessor(
        &mut self,
        bytes: &[u8],
        target: Option<u32>,
        component_type: u32,
        count: usize,
        kind: &str,
        extra: Value,
    ) -> usize {
        let view = self.view(bytes, target);
        let mut accessor = json!({"bufferView": view, "componentType": component_type, "count": count, "type": kind});
        if let (Value::Object(a), Value::Object(e)) = (&mut accessor, extra) {
            a.extend(e);
        }
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    /// A float VEC3 accessor with the `min` and `max` glTF asks of
    /// positions (harmless on other attributes).
    pub fn vec3(&mut self, values: &[[f32; 3]], target: Option<u32>) -> usize {
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in values {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let bounds = if values.is_empty() {
            json!({})
        } else {
            json!({"min": lo, "max": hi})
        };
        self.accessor(
            bytemuck::cast_slice(values),
            target,
            FLOAT,
            values.len(),
            "VEC3",
            bounds,
        )
    }

    /// The container: `doc` with the buffer views, accessors and the one
    /// buffer added, then the binary chunk.
    pub fn finish(mut self, mut doc: Value) -> Result<Vec<u8>> {
        self.align();
        doc["bufferViews"] = json!(self.views);
        doc["accessors"] = json!(self.accessors);
        doc["buffers"] = json!([{"byteLength": self.bin.len()}]);
        let mut text = serde_json::to_vec(&doc).map_err(|e| Error::Input(e.to_string()))?;
        while !text.len().is_multiple_of(4) {
            text.push(b' ');
        }
        let total = 12 + 8 + text.len() + 8 + self.bin.len();
        let length = |n: usize| {
            u32::try_from(n)
                .map_err(|_| Error::Input(format!("a glb of {n} bytes is past glTF's 4 GiB")))
        };
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&length(total)?.to_le_bytes());
        out.extend_from_slice(&length(text.len())?.to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&text);
        out.extend_from_slice(&length(self.bin.len())?.to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&self.bin);
        Ok(out)
    }

    fn align(&mut self) {
        while !self.bin.len().is_multiple_of(8) {
            self.bin.push(0);
        }
    }
}

/// The JSON document of a glb (for tests and checks): `None` when the bytes
/// are not a glb.
pub fn document(glb: &[u8]) -> Option<Value> {
    let word = |at: usize| Some(u32::from_le_bytes(glb.get(at..at + 4)?.try_into().ok()?));
    if glb.get(..4)? != b"glTF" || glb.get(16..20)? != b"JSON" {
        return None;
    }
    let length = word(12)? as usize;
    serde_json::from_slice(glb.get(20..20 + length)?).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_are_aligned_and_the_document_reads_back() {
        let mut glb = Glb::default();
        let a = glb.accessor(&[1, 2, 3], None, UNSIGNED_BYTE, 3, "SCALAR", json!({}));
        let b = glb.vec3(&[[1.0, -2.0, 3.0], [0.0, 5.0, -1.0]], Some(ARRAY_BUFFER));
        let bytes = glb.finish(json!({"asset": {"version": "2.0"}})).unwrap();
        let doc = document(&bytes).unwrap();
        assert_eq!((a, b), (0, 1));
        assert_eq!(doc["bufferViews"][1]["byteOffset"], 8);
        assert_eq!(doc["accessors"][1]["min"], json!([0.0, -2.0, -1.0]));
        assert_eq!(doc["accessors"][1]["max"], json!([1.0, 5.0, 3.0]));
        assert_eq!(doc["buffers"][0]["byteLength"], 32);
        assert_eq!(
            u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize,
            bytes.len()
        );
        assert!(document(b"not a glb at all, no").is_none());
    }
}
