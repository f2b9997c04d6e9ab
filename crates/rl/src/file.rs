//! The binary container shared by policy files and checkpoints, written atomically.
//!
//! ```text
//! magic (8 bytes) | format version (u32 LE) | header length (u64 LE) | header (JSON)
//! | array count (u64 LE) | per array: length (u64 LE), f32 LE values | CRC-32 of all before (u32 LE)
//! ```
//! The checksum is checked before anything is parsed, so a truncated or corrupted file is
//! rejected as such rather than misread.

use crate::error::{Result, RlError};
use serde::Serialize;
use serde::de::DeserializeOwned;
use std::path::Path;

/// CRC-32 (IEEE 802.3, as zlib's `crc32`).
pub fn crc32(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

fn bad(path: &Path, reason: impl Into<String>) -> RlError {
    RlError::BadFile {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> RlError + '_ {
    move |source| RlError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Encode a container in memory.
pub fn encode(magic: &[u8; 8], version: u32, header: &impl Serialize, arrays: &[&[f32]]) -> Result<Vec<u8>> {
    let header = serde_json::to_vec(header).map_err(|e| RlError::Config(format!("header: {e}")))?;
    let n_floats: usize = arrays.iter().map(|a| a.len()).sum();
    let mut buf = Vec::with_capacity(32 + header.len() + 8 * arrays.len() + 4 * n_floats);
    buf.extend_from_slice(magic);
    buf.extend_from_slice(&version.to_le_bytes());
    buf.extend_from_slice(&(header.len() as u64).to_le_bytes());
    buf.extend_from_slice(&header);
    buf.extend_from_slice(&(arrays.len() as u64).to_le_bytes());
    for a in arrays {
        buf.extend_from_slice(&(a.len() as u64).to_le_bytes());
        for v in *a {
            buf.extend_from_slice(&v.to_le_bytes());
        }
    }
    let crc = crc32(&buf);
    buf.extend_from_slice(&crc.to_le_bytes());
    Ok(buf)
}

/// [`agvrl_sim::write_atomic`], its error naming `path`.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    agvrl_sim::write_atomic(path, bytes).map_err(io(path))
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8]> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|e| *e <= self.buf.len())
            .ok_or_else(|| bad(self.path, "truncated"))?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn u64(&mut self) -> Result<u64> {
        let b = self.take(8)?;
        Ok(u64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
    }
}

/// Decode a container read from `path`: checks the checksum, magic and that the version is one
/// of `versions`, then parses the header as `H` and returns the arrays.
pub fn decode<H: DeserializeOwned>(
    path: &Path,
    bytes: &[u8],
    magic: &[u8; 8],
    versions: &[u32],
    kind: &str,
) -> Result<(H, Vec<Vec<f32>>)> {
    if bytes.len() < 8 || &bytes[..8] != magic {
        return Err(bad(path, format!("not an agvrl {kind} file (wrong magic bytes)")));
    }
    if bytes.len() < 8 + 4 + 8 + 8 + 4 {
        return Err(bad(path, format!("truncated {kind} file ({} bytes)", bytes.len())));
    }
    let (body, tail) = bytes.split_at(bytes.len() - 4);
    let stored = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
    if crc32(body) != stored {
        return Err(bad(
            path,
            format!("{kind} file is corrupted or truncated (checksum mismatch)"),
        ));
    }
    let got_version = u32::from_le_bytes([body[8], body[9], body[10], body[11]]);
    if !versions.contains(&got_version) {
        return Err(bad(
            path,
            format!("{kind} format version {got_version}, this build reads versions {versions:?}"),
        ));
    }
    let mut r = Reader {
        buf: body,
        pos: 12,
        path,
    };
    let hlen = r.u64()? as usize;
    let header: H = serde_json::from_slice(r.take(hlen)?).map_err(|e| bad(path, format!("header: {e}")))?;
    let n = r.u64()? as usize;
    let mut arrays = Vec::with_capacity(n.min(1 << 16));
    for _ in 0..n {
        let len = r.u64()? as usize;
        let raw = r.take(len.checked_mul(4).ok_or_else(|| bad(path, "array length overflows"))?)?;
        arrays.push(
            raw.chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        );
    }
    if r.pos != body.len() {
        return Err(bad(path, "trailing bytes after the last array"));
    }
    Ok((header, arrays))
}

/// Read and decode the container at `path`.
pub fn read<H: DeserializeOwned>(
    path: &Path,
    magic: &[u8; 8],
    versions: &[u32],
    kind: &str,
) -> Result<(H, Vec<Vec<f32>>)> {
    let bytes = std::fs::read(path).map_err(io(path))?;
    decode(path, &bytes, magic, versions, kind)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_matches_the_standard_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn round_trip_and_every_truncation_is_rejected() {
        let a = [1.0f32, -2.5, 3.25];
        let bytes = encode(b"AGVRLTST", 3, &"hello", &[&a, &[]]).unwrap();
        let p = Path::new("x");
        let (h, arrays): (String, _) = decode(p, &bytes, b"AGVRLTST", &[3], "test").unwrap();
        assert_eq!(h, "hello");
        assert_eq!(arrays, vec![a.to_vec(), vec![]]);
        for n in 0..bytes.len() {
            assert!(
                decode::<String>(p, &bytes[..n], b"AGVRLTST", &[3], "test").is_err(),
                "{n}"
            );
        }
        let mut flipped = bytes.clone();
        flipped[30] ^= 1;
        assert!(decode::<String>(p, &flipped, b"AGVRLTST", &[3], "test").is_err());
        assert!(decode::<String>(p, &bytes, b"AGVRLTST", &[4], "test").is_err());
    }
}
