//! The binary container of fuzzyq's files: a magic tag naming the kind of file, a format
//! version, the payload's length and CRC-32, then the payload.
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic tag (its first byte `0x89` catches 7-bit and text-mode mangling) |
//! | 4 | format version, `u32` little-endian |
//! | 8 | payload length in bytes, `u64` little-endian |
//! | 4 | CRC-32 of the payload, `u32` little-endian |
//! | n | payload |

use std::io::Read as _;
use std::path::Path;

/// Bytes before the payload.
pub(crate) const HEADER_LEN: usize = 8 + 4 + 8 + 4;

/// The container of `payload`.
#[cfg(test)]
pub(crate) fn encode(magic: &[u8; 8], version: u32, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
    out.resize(HEADER_LEN, 0);
    out.extend_from_slice(payload);
    seal(magic, version, out)
}

/// The container of `value`'s postcard serialisation, built in one buffer of the exact size
/// (the payload is neither regrown nor copied: a robots' policy file is 188 MB).
pub(crate) fn encode_postcard<T: serde::Serialize + ?Sized>(
    magic: &[u8; 8],
    version: u32,
    value: &T,
) -> postcard::Result<Vec<u8>> {
    let size = postcard::experimental::serialized_size(value)?;
    let mut out = Vec::with_capacity(HEADER_LEN + size);
    out.resize(HEADER_LEN, 0);
    let out = postcard::to_extend(value, out)?;
    Ok(seal(magic, version, out))
}

/// The value of a whole payload: postcard decodes a value from the front of its input and
/// would ignore bytes after it, so a payload with any left over is refused. The error says in
/// words what is wrong (postcard's own messages, such as "Found a bool that wasn't 0 or 1",
/// name its internals, not the file).
pub(crate) fn decode_postcard<T: serde::de::DeserializeOwned>(payload: &[u8]) -> Result<T, String> {
    use postcard::Error as E;
    match postcard::take_from_bytes(payload) {
        Ok((value, [])) => Ok(value),
        Ok((_, rest)) => Err(format!(
            "its payload has {} bytes after its content",
            rest.len()
        )),
        Err(E::DeserializeUnexpectedEnd) => Err("its payload ends inside its content".into()),
        Err(_) => Err(
            "its payload holds a value of the wrong kind or out of range (a damaged \
             file, or one a newer fuzzyq wrote)"
                .into(),
        ),
    }
}

/// Writes the header of the container whose payload follows `HEADER_LEN` placeholder bytes
/// in `out`.
fn seal(magic: &[u8; 8], version: u32, mut out: Vec<u8>) -> Vec<u8> {
    let (header, payload) = out.split_at_mut(HEADER_LEN);
    let crc = crc32fast::hash(payload);
    header[..8].copy_from_slice(magic);
    header[8..12].copy_from_slice(&version.to_le_bytes());
    header[12..20].copy_from_slice(&(payload.len() as u64).to_le_bytes());
    header[20..24].copy_from_slice(&crc.to_le_bytes());
    out
}

/// What is wrong with a container's bytes.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum Damage {
    /// Shorter than its header says (or than a header).
    Truncated {
        /// Bytes present.
        found: u64,
        /// Bytes expected.
        expected: u64,
    },
    /// Bytes after the payload.
    Trailing(u64),
    /// The payload does not match its CRC-32.
    Checksum,
}

/// Splits a container (whose tag the caller has checked) into its version and its payload,
/// checking length and checksum.
pub(crate) fn split(bytes: &[u8]) -> Result<(u32, &[u8]), Damage> {
    let found = bytes.len() as u64;
    let header = bytes.get(..HEADER_LEN).ok_or(Damage::Truncated {
        found,
        expected: HEADER_LEN as u64,
    })?;
    let field = |r: std::ops::Range<usize>| {
        header[r]
            .iter()
            .rev()
            .fold(0u64, |acc, &b| (acc << 8) | u64::from(b))
    };
    let (version, len, crc) = (field(8..12) as u32, field(12..20), field(20..24) as u32);
    let expected = (HEADER_LEN as u64).saturating_add(len);
    if found < expected {
        return Err(Damage::Truncated { found, expected });
    }
    if found > expected {
        return Err(Damage::Trailing(found - expected));
    }
    let payload = &bytes[HEADER_LEN..];
    if crc32fast::hash(payload) != crc {
        return Err(Damage::Checksum);
    }
    Ok((version, payload))
}

/// What [`read`] found.
pub(crate) enum Read {
    /// A container with the expected tag: the header and at most one byte more than the
    /// payload it announces.
    Container(Vec<u8>),
    /// Something else: its first bytes (at most a header's length) and the rest, unread.
    Other(Vec<u8>, std::fs::File),
}

/// Reads the file at `path` once (a pipe works): if it starts with `magic`, the header and as
/// many bytes as its header announces and one more (so [`split`] sees trailing bytes; a lying
/// header cannot make it read forever), else only its first bytes (the rest is the caller's).
pub(crate) fn read(path: &Path, magic: &[u8; 8]) -> std::io::Result<Read> {
    let mut file = crate::fs::open(path)?;
    let mut bytes = Vec::with_capacity(HEADER_LEN);
    (&mut file)
        .take(HEADER_LEN as u64)
        .read_to_end(&mut bytes)?;
    if bytes.len() < magic.len() || bytes[..magic.len()] != magic[..] {
        return Ok(Read::Other(bytes, file));
    }
    if bytes.len() == HEADER_LEN {
        let len = u64::from_le_bytes(bytes[12..20].try_into().unwrap_or_default());
        // At most one byte beyond the announced payload: enough to see trailing bytes.
        file.take(len.saturating_add(1)).read_to_end(&mut bytes)?;
    }
    Ok(Read::Container(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_names_the_damage() {
        let magic = *b"\x89TESTFQ\n";
        let bytes = encode(&magic, 7, b"payload");
        assert_eq!(split(&bytes), Ok((7, &b"payload"[..])));
        assert_eq!(
            split(&bytes[..bytes.len() - 2]),
            Err(Damage::Truncated {
                found: bytes.len() as u64 - 2,
                expected: bytes.len() as u64
            })
        );
        assert!(matches!(split(&bytes[..5]), Err(Damage::Truncated { .. })));
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(split(&longer), Err(Damage::Trailing(1)));
        let mut flipped = bytes.clone();
        *flipped.last_mut().unwrap() ^= 1;
        assert_eq!(split(&flipped), Err(Damage::Checksum));
        let mut lying = bytes;
        lying[12..20].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(matches!(split(&lying), Err(Damage::Truncated { .. })));
    }

    /// The container built in place holds exactly the bytes of the serialised payload behind
    /// the header `encode` writes for them, for payloads empty, short and long.
    #[test]
    fn built_in_place_is_the_container_of_the_serialised_payload() {
        let magic = *b"\x89TESTFQ\n";
        let values: Vec<f32> = (0..100_000u32).map(|i| i as f32 * 0.37 - 5.0).collect();
        let cases: [(&str, &[f32]); 3] =
            [("empty", &[]), ("short", &values[..3]), ("long", &values)];
        for (name, v) in cases {
            let payload = postcard::to_stdvec(&(name, v)).unwrap();
            let built = encode_postcard(&magic, 3, &(name, v)).unwrap();
            assert_eq!(built, encode(&magic, 3, &payload), "{name}");
            assert_eq!(&built[..8], &magic);
            assert_eq!(split(&built), Ok((3, &payload[..])), "{name}");
            assert_eq!(built.len(), built.capacity(), "{name}: sized exactly");
        }
    }
}
