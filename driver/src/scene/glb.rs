//! The binary glTF container every glb guidebake writes goes through: `prepare --write-gltf`
//! and `view` (the source document rewritten, or a new one for an OBJ scene and `demo`'s room:
//! [`super::gltf_write`]) and `synth`'s city (`crate::synth`). One writer of the parts they
//! share:
//! - the binary chunk ([`GlbBuffer`]), filled view by view, each view starting on a 4-byte
//!   boundary (zeros between), and the JSON of its buffer views ([`view`]) and accessors
//!   ([`accessor`]), all in buffer 0;
//! - the file ([`write`]): glTF 2.0's GLB framing — a 12-byte header (`glTF`, version 2, the
//!   total length), the JSON chunk padded with spaces to 4 bytes, the BIN chunk padded with
//!   zeros — published whole ([`crate::atomic`]: nothing is left at the path on failure),
//!   written from its parts without copying the binary chunk again.

use std::io;
use std::path::Path;

use serde_json::{Value, json};

/// `bufferView.target` of vertex attributes.
pub const ARRAY_BUFFER: u32 = 34962;
/// `bufferView.target` of indices.
pub const ELEMENT_ARRAY_BUFFER: u32 = 34963;
/// `accessor.componentType` of `f32` components.
pub const FLOAT: u32 = 5126;
/// `accessor.componentType` of `u32` components.
pub const UNSIGNED_INT: u32 = 5125;

/// The binary chunk of a glb being built, and the buffer views [`GlbBuffer::push_view`] made
/// into it.
#[derive(Debug, Default)]
pub struct GlbBuffer {
    bin: Vec<u8>,
    views: Vec<Value>,
}

impl GlbBuffer {
    /// Appends `bytes` at the chunk's next 4-byte boundary; returns where they start.
    pub fn append(&mut self, bytes: &[u8]) -> usize {
        self.pad();
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        offset
    }

    /// Appends `bytes` as a new buffer view ([`view`]); returns the view's index among the
    /// views made here.
    pub fn push_view(&mut self, bytes: &[u8], stride: Option<usize>, target: Option<u32>) -> usize {
        let offset = self.append(bytes);
        self.views.push(view(offset, bytes.len(), stride, target));
        self.views.len() - 1
    }

    /// The chunk's bytes, padded to 4, and the views made by [`GlbBuffer::push_view`].
    pub fn finish(mut self) -> (Vec<u8>, Vec<Value>) {
        self.pad();
        (self.bin, self.views)
    }

    fn pad(&mut self) {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
    }
}

/// A buffer view of buffer 0: `length` bytes at `offset`, with the byte stride and target
/// where given.
pub fn view(offset: usize, length: usize, stride: Option<usize>, target: Option<u32>) -> Value {
    let mut view = json!({ "buffer": 0, "byteOffset": offset, "byteLength": length });
    if let Some(s) = stride {
        view["byteStride"] = s.into();
    }
    if let Some(t) = target {
        view["target"] = t.into();
    }
    view
}

/// An accessor of `count` elements of type `kind` (`"VEC3"`, `"SCALAR"`, …) and component
/// type `component` in buffer view `view`, with per-component `bounds` (min, max) where given
/// (glTF asks for them on `POSITION`).
pub fn accessor(
    view: usize,
    component: u32,
    count: usize,
    kind: &str,
    bounds: Option<([f32; 3], [f32; 3])>,
) -> Value {
    let mut a =
        json!({ "bufferView": view, "componentType": component, "count": count, "type": kind });
    if let Some((lo, hi)) = bounds {
        a["min"] = json!(lo);
        a["max"] = json!(hi);
    }
    a
}

/// Writes the glb of document `json` and binary chunk `bin` to `out`, whole or not at all.
///
/// # Errors
/// The I/O error of writing, syncing or renaming the file.
pub fn write(out: &Path, mut json: Vec<u8>, bin: &[u8]) -> io::Result<()> {
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let padding = bin.len().next_multiple_of(4) - bin.len();
    let total = 12 + 8 + json.len() + 8 + bin.len() + padding;
    let length = |n: usize| {
        u32::try_from(n)
            .map(u32::to_le_bytes)
            .map_err(|_| io::Error::other(format!("{n} bytes: more than a glb holds (4 GiB)")))
    };
    let header = [&b"glTF"[..], &2u32.to_le_bytes(), &length(total)?].concat();
    let json_header = [&length(json.len())?[..], b"JSON"].concat();
    let bin_header = [&length(bin.len() + padding)?[..], b"BIN\0"].concat();
    let zeros = [0u8; 3];
    crate::atomic::write_parts(
        out,
        &[
            &header,
            &json_header,
            &json,
            &bin_header,
            bin,
            &zeros[..padding],
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The framing is glTF's own (`gltf::binary::Glb`, which `prepare --write-gltf` wrote
    /// through before): the same bytes for every padding of the JSON and the binary chunk.
    #[test]
    fn write_frames_as_the_gltf_crate_does() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("x.glb");
        for json_len in 0..5 {
            for bin_len in 0..5 {
                let json: Vec<u8> = (0..json_len).map(|i| b'a' + i).collect();
                let bin: Vec<u8> = (0..bin_len).map(|i| 1 + i).collect();
                write(&out, json.clone(), &bin).unwrap();
                let glb = ::gltf::binary::Glb {
                    header: ::gltf::binary::Header {
                        magic: *b"glTF",
                        version: 2,
                        length: 0,
                    },
                    json: json.into(),
                    bin: Some(bin.into()),
                };
                assert_eq!(std::fs::read(&out).unwrap(), glb.to_vec().unwrap());
            }
        }
    }

    #[test]
    fn views_start_on_four_byte_boundaries() {
        let mut buffer = GlbBuffer::default();
        assert_eq!(buffer.push_view(&[1, 2, 3], None, Some(ARRAY_BUFFER)), 0);
        assert_eq!(buffer.append(&[4; 6]), 4);
        assert_eq!(buffer.push_view(&[5], Some(4), None), 1);
        let (bin, views) = buffer.finish();
        assert_eq!(bin, [1, 2, 3, 0, 4, 4, 4, 4, 4, 4, 0, 0, 5, 0, 0, 0]);
        assert_eq!(
            views,
            [
                json!({ "buffer": 0, "byteOffset": 0, "byteLength": 3, "target": ARRAY_BUFFER }),
                json!({ "buffer": 0, "byteOffset": 12, "byteLength": 1, "byteStride": 4 }),
            ]
        );
    }
}
