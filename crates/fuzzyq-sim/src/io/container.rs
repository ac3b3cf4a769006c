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

/// The container of `value`'s postcard serialisation, built in one buffer of the exact size:
/// serde's bytes, which the files' bulk encoding ([`Encoder`]) is tested against.
#[cfg(test)]
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

/// Writes the container of `value`'s postcard serialisation to `out` from its position on,
/// as it is encoded ([`write_encoded`] of the value as serde gives it).
#[cfg(test)]
pub(crate) fn write_postcard<T, W>(
    out: W,
    magic: &[u8; 8],
    version: u32,
    value: &T,
) -> std::io::Result<W>
where
    T: serde::Serialize + ?Sized,
    W: std::io::Write + std::io::Seek,
{
    write_encoded(out, magic, version, |e| e.value(value))
}

/// Writes the container of the payload `encode` writes to `out` from its position on, as it
/// is encoded: a placeholder header, the payload through a buffer, its CRC-32 and a count,
/// then the header over the placeholder. The payload is never held whole (three point masses
/// on the paper's cores make a 48 GB policy file).
pub(crate) fn write_encoded<W>(
    out: W,
    magic: &[u8; 8],
    version: u32,
    encode: impl FnOnce(&mut Encoder<&mut std::io::BufWriter<Summed<W>>>) -> std::io::Result<()>,
) -> std::io::Result<W>
where
    W: std::io::Write + std::io::Seek,
{
    use std::io::SeekFrom;
    let mut sum = Summed {
        inner: out,
        crc: crc32fast::Hasher::new(),
        len: 0,
    };
    let start = sum.inner.stream_position()?;
    sum.inner.write_all(&[0; HEADER_LEN])?;
    // Postcard writes a value at a time: buffered, the checksum runs over large chunks.
    let mut buffered = std::io::BufWriter::with_capacity(1 << 20, sum);
    encode(&mut Encoder::new(&mut buffered))?;
    let sum = buffered.into_inner().map_err(|e| e.into_error())?;
    let mut out = sum.inner;
    out.seek(SeekFrom::Start(start))?;
    out.write_all(&header(magic, version, sum.len, sum.crc.finalize()))?;
    out.seek(SeekFrom::Start(start + HEADER_LEN as u64 + sum.len))?;
    out.flush()?;
    Ok(out)
}

/// Writes a payload as postcard encodes it, the per-core arrays in bulk.
///
/// Postcard encodes a struct or a tuple as its fields one after the other, an enum as its
/// variant's index (a varint) then its fields, and a slice of `n` numbers as `n` (a varint)
/// then each number: `f32` and `f64` as their little-endian bytes, `u32` as a varint. So a
/// payload can be written field by field, the small fields through serde ([`Self::value`])
/// and the arrays of a value per core ([`Self::floats`], [`Self::u32s`]) by a
/// loop that fills a buffer and writes it whole, where serde would make a call per number
/// (the robots' policy: 75 million of them, 0.16 s against 0.03 s). The bytes are serde's:
/// each payload that is written so has a test that says so.
pub(crate) struct Encoder<W> {
    out: W,
    buf: Vec<u8>,
}

/// The floating-point types whose values postcard encodes as their little-endian bytes.
pub(crate) trait Float:
    bytemuck::Pod + serde::Serialize + serde::de::DeserializeOwned
{
}
impl Float for f32 {}
impl Float for f64 {}

/// Numbers an [`Encoder`] encodes per write of its buffer.
const ENCODED_AT_ONCE: usize = 1 << 16;

impl<W: std::io::Write> Encoder<W> {
    fn new(out: W) -> Self {
        Self {
            out,
            buf: Vec::new(),
        }
    }

    /// `value` as serde and postcard encode it.
    pub(crate) fn value<T: serde::Serialize + ?Sized>(&mut self, value: &T) -> std::io::Result<()> {
        to_writer(value, &mut self.out)
    }

    /// The index of an enum's variant, as postcard encodes it before the variant's fields.
    pub(crate) fn variant(&mut self, index: u32) -> std::io::Result<()> {
        self.value(&index)
    }

    /// A slice of `f32` or `f64` (its length, then each value's little-endian bytes: on a
    /// little-endian host the slice's own bytes, written a buffer's worth at a time).
    pub(crate) fn floats<T: Float>(&mut self, values: &[T]) -> std::io::Result<()> {
        if cfg!(target_endian = "big") {
            return self.value(values);
        }
        self.value(&values.len())?;
        for chunk in values.chunks(ENCODED_AT_ONCE) {
            self.out.write_all(bytemuck::cast_slice(chunk))?;
        }
        Ok(())
    }

    /// A slice of `u32` (its length, then each value as a varint: 7 bits a byte, low first,
    /// the high bit set on every byte but the last). A buffer's worth of values below 128
    /// (the joint actions of the robots) is a byte each, copied in one loop; below 16,384
    /// (the paper's 625) one or two bytes each, both written and the position moved by the
    /// value's length, without a branch per value.
    pub(crate) fn u32s(&mut self, values: &[u32]) -> std::io::Result<()> {
        self.value(&values.len())?;
        for chunk in values.chunks(ENCODED_AT_ONCE) {
            let largest = chunk.iter().copied().max().unwrap_or(0);
            self.buf.clear();
            if largest < 0x80 {
                self.buf.extend(chunk.iter().map(|&x| x as u8));
            } else if largest < 0x4000 {
                self.buf.resize(2 * chunk.len() + 1, 0);
                let mut at = 0;
                for &x in chunk {
                    let long = usize::from(x >= 0x80);
                    self.buf[at] = x as u8 & 0x7f | (long as u8) << 7;
                    self.buf[at + 1] = (x >> 7) as u8;
                    at += 1 + long;
                }
                self.buf.truncate(at);
            } else {
                for &x in chunk {
                    let mut x = x;
                    while x >= 0x80 {
                        self.buf.push(x as u8 | 0x80);
                        x >>= 7;
                    }
                    self.buf.push(x as u8);
                }
            }
            self.out.write_all(&self.buf)?;
        }
        Ok(())
    }
}

/// The postcard flavor of [`Encoder::value`]: postcard's own writer flavor, but a write error
/// is kept (postcard's would report a full disk as a full buffer) and ends the encoding.
struct KeepError<W> {
    out: W,
    error: Option<std::io::Error>,
}

impl<W: std::io::Write> KeepError<W> {
    #[inline(always)]
    fn kept(&mut self, written: std::io::Result<()>) -> postcard::Result<()> {
        match written {
            Ok(()) => Ok(()),
            Err(e) => self.keep(e),
        }
    }

    #[cold]
    fn keep(&mut self, e: std::io::Error) -> postcard::Result<()> {
        self.error = Some(e);
        Err(postcard::Error::SerializeBufferFull)
    }
}

impl<W: std::io::Write> postcard::ser_flavors::Flavor for KeepError<W> {
    type Output = ();

    #[inline(always)]
    fn try_push(&mut self, byte: u8) -> postcard::Result<()> {
        let written = self.out.write_all(&[byte]);
        self.kept(written)
    }

    #[inline(always)]
    fn try_extend(&mut self, bytes: &[u8]) -> postcard::Result<()> {
        let written = self.out.write_all(bytes);
        self.kept(written)
    }

    fn finalize(self) -> postcard::Result<()> {
        Ok(())
    }
}

/// `value`'s postcard serialisation written to `out`, a value at a time (buffer `out`); a
/// write error is the writer's own.
fn to_writer<T: serde::Serialize + ?Sized>(
    value: &T,
    out: impl std::io::Write,
) -> std::io::Result<()> {
    let mut ser = postcard::Serializer {
        output: KeepError { out, error: None },
    };
    let encoded = value.serialize(&mut ser);
    match ser.output.error {
        Some(e) => Err(e),
        None => encoded.map_err(std::io::Error::other),
    }
}

/// A writer or reader that counts and checksums what passes through it.
pub(crate) struct Summed<W> {
    inner: W,
    crc: crc32fast::Hasher,
    len: u64,
}

impl<R: std::io::Read> std::io::Read for Summed<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.crc.update(&buf[..n]);
        self.len += n as u64;
        Ok(n)
    }
}

impl<W: std::io::Write> std::io::Write for Summed<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.crc.update(&buf[..n]);
        self.len += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// The header of a container whose payload has `len` bytes and CRC-32 `crc`.
fn header(magic: &[u8; 8], version: u32, len: u64, crc: u32) -> [u8; HEADER_LEN] {
    let mut h = [0; HEADER_LEN];
    h[..8].copy_from_slice(magic);
    h[8..12].copy_from_slice(&version.to_le_bytes());
    h[12..20].copy_from_slice(&len.to_le_bytes());
    h[20..24].copy_from_slice(&crc.to_le_bytes());
    h
}

/// [`decode_payload`] of a value decoded whole by serde: the tests' reference for the
/// payloads decoded in bulk.
#[cfg(test)]
pub(crate) fn decode_postcard<T: serde::de::DeserializeOwned>(payload: &[u8]) -> Result<T, String> {
    decode_payload::<Serde<T>>(payload).map(|s| s.0)
}

/// Payloads of at least this many bytes are decoded as they are read
/// ([`decode_streamed_as`], policy files and checkpoints), smaller ones read whole first. The
/// content is then held once, not also as the file's bytes (three point masses on the
/// paper's cores: a 48 GB policy), and with the arrays decoded in bulk a file loads faster
/// so (Zen 4, `cargo bench --bench files -- policy_read`: the robots' 188 MB policy in
/// 209 ms against 356 ms read whole first).
pub(crate) const STREAM_FROM: u64 = 1 << 20;

/// The value of a whole payload, as `T` decodes it ([`Decode`]): postcard decodes a value
/// from the front of its input and would ignore bytes after it, so a payload with any left
/// over is refused. The error says in words what is wrong (postcard's own messages, such as
/// "Found a bool that wasn't 0 or 1", name its internals, not the file).
pub(crate) fn decode_payload<T: Decode>(payload: &[u8]) -> Result<T, String> {
    let mut d = Decoder {
        src: Cursor { rest: payload },
    };
    match T::decode(&mut d) {
        Ok(value) if d.src.rest.is_empty() => Ok(value),
        Ok(_) => Err(left_over(d.src.rest.len() as u64)),
        Err(e) => Err(undecodable(&e)),
    }
}

/// What is wrong with a payload that holds `n` bytes after its content.
fn left_over(n: u64) -> String {
    format!("its payload has {n} bytes after its content")
}

/// What is wrong with a payload postcard cannot decode, in words.
fn undecodable(e: &postcard::Error) -> String {
    match e {
        postcard::Error::DeserializeUnexpectedEnd => "its payload ends inside its content".into(),
        _ => "its payload holds a value of the wrong kind or out of range (a damaged file, or \
              one a newer fuzzyq wrote)"
            .into(),
    }
}

/// Why [`decode_streamed`] failed.
#[derive(Debug)]
pub(crate) enum Streamed {
    /// Reading failed.
    Io(std::io::Error),
    /// The container is damaged (found in the order [`split`] checks).
    Damage(Damage),
    /// The payload is intact but does not decode ([`decode_payload`]'s words).
    Content(String),
}

/// [`split`] and [`decode_payload`] of a container read as it is decoded: `file` is just past
/// a header announcing a payload of `len` bytes with CRC-32 `crc`. The payload is never held
/// whole (a policy of three point masses on the paper's cores is 48 GB), and the damage is
/// found and named as [`split`] would: a short file, bytes after the payload, a checksum
/// mismatch, then content that does not decode.
pub(crate) fn decode_streamed<T: serde::de::DeserializeOwned>(
    file: impl std::io::Read,
    len: u64,
    crc: u32,
) -> Result<T, Streamed> {
    decode_streamed_as::<Serde<T>>(file, len, crc).map(|s| s.0)
}

/// [`decode_streamed`] of a payload decoded by `T`'s own [`Decode`].
pub(crate) fn decode_streamed_as<T: Decode>(
    file: impl std::io::Read,
    len: u64,
    crc: u32,
) -> Result<T, Streamed> {
    decode_streamed_in(file, len, crc, 1 << 20)
}

/// [`decode_streamed_as`] through a buffer of `capacity` bytes (the tests' small ones split
/// values between two reads).
pub(crate) fn decode_streamed_in<T: Decode>(
    file: impl std::io::Read,
    len: u64,
    crc: u32,
    capacity: usize,
) -> Result<T, Streamed> {
    let summed = Summed {
        inner: file.take(len),
        crc: crc32fast::Hasher::new(),
        len: 0,
    };
    let mut flavor = Stream {
        reader: std::io::BufReader::with_capacity(capacity, summed),
        left: len,
        temp: Vec::new(),
    };
    let decoded = T::decode(&mut Decoder { src: &mut flavor });
    // The rest of the payload, read through the checksum: what the content left over.
    let rest = std::io::copy(&mut flavor.reader, &mut std::io::sink()).map_err(Streamed::Io)?;
    let summed = flavor.reader.into_inner();
    if summed.len < len {
        return Err(Streamed::Damage(Damage::Truncated {
            found: HEADER_LEN as u64 + summed.len,
            expected: (HEADER_LEN as u64).saturating_add(len),
        }));
    }
    let mut file = summed.inner.into_inner();
    if file.read(&mut [0]).map_err(Streamed::Io)? > 0 {
        // At least one byte follows; as [`read`], no more is read to count them.
        return Err(Streamed::Damage(Damage::Trailing(1)));
    }
    if summed.crc.finalize() != crc {
        return Err(Streamed::Damage(Damage::Checksum));
    }
    match decoded {
        Ok(_) if rest > 0 => Err(Streamed::Content(left_over(rest))),
        Ok(value) => Ok(value),
        Err(e) => Err(Streamed::Content(undecodable(&e))),
    }
}

/// The postcard flavor of [`decode_streamed`]: bytes from a buffered reader, at most `left`
/// of them; a string's bytes are read into `temp`, which grows to the longest one as its
/// bytes arrive (a damaged length allocates no more than the file holds, whatever the header
/// announces).
/// Owned values only: nothing can borrow from a stream.
struct Stream<R> {
    reader: R,
    left: u64,
    temp: Vec<u8>,
}

impl<R: std::io::Read> Stream<R> {
    fn fill(&mut self, out: &mut [u8]) -> postcard::Result<()> {
        if out.len() as u64 > self.left {
            return Err(postcard::Error::DeserializeUnexpectedEnd);
        }
        self.reader
            .read_exact(out)
            .map_err(|_| postcard::Error::DeserializeUnexpectedEnd)?;
        self.left -= out.len() as u64;
        Ok(())
    }
}

impl<'s: 'de, 'de, R: std::io::Read + 'de> postcard::de_flavors::Flavor<'de> for &'s mut Stream<R> {
    type Remainder = ();
    type Source = ();

    fn pop(&mut self) -> postcard::Result<u8> {
        let mut b = [0];
        self.fill(&mut b)?;
        Ok(b[0])
    }

    fn try_take_n(&mut self, _ct: usize) -> postcard::Result<&'de [u8]> {
        // Only a value borrowing from the input asks for this; fuzzyq's files hold none.
        Err(postcard::Error::DeserializeBadEncoding)
    }

    fn try_take_n_temp<'a>(&'a mut self, ct: usize) -> postcard::Result<&'a [u8]>
    where
        'de: 'a,
    {
        if ct as u64 > self.left {
            return Err(postcard::Error::DeserializeUnexpectedEnd);
        }
        // Grown as the bytes arrive, not to the length a damaged header and string claim
        // (which a short file can set to a terabyte: an abort, not an error).
        self.temp.clear();
        let got = (&mut self.reader)
            .take(ct as u64)
            .read_to_end(&mut self.temp)
            .map_err(|_| postcard::Error::DeserializeUnexpectedEnd)?;
        if got < ct {
            return Err(postcard::Error::DeserializeUnexpectedEnd);
        }
        self.left -= ct as u64;
        Ok(&self.temp)
    }

    fn finalize(self) -> postcard::Result<()> {
        Ok(())
    }
}

/// A payload's content decoded field by field ([`Decoder`]), the mirror of what an
/// [`Encoder`] writes.
pub(crate) trait Decode: Sized {
    /// The value at the front of `d`'s payload.
    fn decode<S: Source>(d: &mut Decoder<S>) -> postcard::Result<Self>;
}

/// A value decoded whole by serde ([`Decoder::value`]).
pub(crate) struct Serde<T>(pub(crate) T);

impl<T: serde::de::DeserializeOwned> Decode for Serde<T> {
    fn decode<S: Source>(d: &mut Decoder<S>) -> postcard::Result<Self> {
        d.value().map(Serde)
    }
}

/// Where a [`Decoder`] reads: a payload in memory ([`Cursor`]) or read from a file as it is
/// decoded ([`Stream`]).
pub(crate) trait Source {
    /// The next value as serde and postcard decode it.
    fn value<T: serde::de::DeserializeOwned>(&mut self) -> postcard::Result<T>;
    /// The payload's next bytes that are at hand (none only at its end).
    fn at_hand(&mut self) -> postcard::Result<&[u8]>;
    /// Moves past `n` bytes of [`Source::at_hand`]'s.
    fn consume(&mut self, n: usize);
    /// Bytes of the payload not yet decoded (as its header announces, for a stream).
    fn left(&self) -> u64;
}

/// A payload in memory.
pub(crate) struct Cursor<'a> {
    rest: &'a [u8],
}

impl Source for Cursor<'_> {
    fn value<T: serde::de::DeserializeOwned>(&mut self) -> postcard::Result<T> {
        let mut de = postcard::Deserializer::from_bytes(self.rest);
        let value = T::deserialize(&mut de)?;
        self.rest = de.finalize()?;
        Ok(value)
    }

    fn at_hand(&mut self) -> postcard::Result<&[u8]> {
        Ok(self.rest)
    }

    fn consume(&mut self, n: usize) {
        self.rest = &self.rest[n..];
    }

    fn left(&self) -> u64 {
        self.rest.len() as u64
    }
}

impl<R: std::io::BufRead> Source for &mut Stream<R> {
    fn value<T: serde::de::DeserializeOwned>(&mut self) -> postcard::Result<T> {
        T::deserialize(&mut postcard::Deserializer::from_flavor(&mut **self))
    }

    fn at_hand(&mut self) -> postcard::Result<&[u8]> {
        let left = self.left;
        let buf = self
            .reader
            .fill_buf()
            .map_err(|_| postcard::Error::DeserializeUnexpectedEnd)?;
        Ok(&buf[..buf.len().min(usize::try_from(left).unwrap_or(usize::MAX))])
    }

    fn consume(&mut self, n: usize) {
        self.reader.consume(n);
        self.left -= n as u64;
    }

    fn left(&self) -> u64 {
        self.left
    }
}

/// Reads a payload as postcard encodes it ([`Encoder`]), the small fields through serde
/// ([`Self::value`]) and the arrays of a value per core in bulk ([`Self::floats`],
/// [`Self::u32s`]), where serde would make a call per number (the robots' policy: 75
/// million of them). Every error is postcard's for the same bytes, or one of the same kind
/// (the payload ending early, or a value out of range), which is all a file's error names.
pub(crate) struct Decoder<S> {
    src: S,
}

impl<S: Source> Decoder<S> {
    /// The next value as serde and postcard decode it.
    pub(crate) fn value<T: serde::de::DeserializeOwned>(&mut self) -> postcard::Result<T> {
        self.src.value()
    }

    /// The index of an enum's variant ([`Encoder::variant`]).
    pub(crate) fn variant(&mut self) -> postcard::Result<u32> {
        self.value()
    }

    /// A `Vec` of `n` values that take at least `size` bytes each, its room reserved at
    /// once where the payload can hold them (so a damaged length allocates nothing it would
    /// not fill, and one that fits no memory falls back on growing as values arrive).
    fn room<T>(&self, n: usize, size: u64) -> Vec<T> {
        let mut out = Vec::new();
        if (n as u64).saturating_mul(size) <= self.src.left() {
            let _ = out.try_reserve_exact(n);
        }
        out
    }

    /// A `Vec` of `f32` or `f64` ([`Encoder::floats`]): its length, then the values'
    /// little-endian bytes, copied as they are at hand.
    pub(crate) fn floats<T: Float>(&mut self) -> postcard::Result<Vec<T>> {
        if cfg!(target_endian = "big") {
            return self.value();
        }
        let n: usize = self.value()?;
        let size = std::mem::size_of::<T>();
        let mut out = self.room(n, size as u64);
        while out.len() < n {
            let buf = self.src.at_hand()?;
            let k = (buf.len() / size).min(n - out.len());
            if k == 0 {
                // The payload's end, or a value split between two reads.
                out.push(self.value()?);
                continue;
            }
            let start = out.len();
            out.resize(start + k, T::zeroed());
            bytemuck::cast_slice_mut::<T, u8>(&mut out[start..]).copy_from_slice(&buf[..k * size]);
            self.src.consume(k * size);
        }
        Ok(out)
    }

    /// A `Vec` of `u32` ([`Encoder::u32s`]): its length, then each value's varint, decoded
    /// in one loop over the bytes at hand, as postcard decodes it (at most 5 bytes, the last
    /// of which holds at most 4 bits).
    pub(crate) fn u32s(&mut self) -> postcard::Result<Vec<u32>> {
        let n: usize = self.value()?;
        let mut out = self.room(n, 1);
        while out.len() < n {
            let buf = self.src.at_hand()?;
            let mut at = 0;
            while out.len() < n && at < buf.len() {
                let b = buf[at];
                if b < 0x80 {
                    out.push(u32::from(b));
                    at += 1;
                    continue;
                }
                match varint_u32(&buf[at..]) {
                    Some(Ok((x, len))) => {
                        out.push(x);
                        at += len;
                    }
                    Some(Err(e)) => return Err(e),
                    None => break,
                }
            }
            self.src.consume(at);
            if at == 0 {
                // The payload's end, or a value split between two reads.
                out.push(self.value()?);
            }
        }
        Ok(out)
    }
}

/// The `u32` varint at the front of `bytes` and its length, postcard's error where it is
/// not one, or `None` where `bytes` end inside it.
fn varint_u32(bytes: &[u8]) -> Option<postcard::Result<(u32, usize)>> {
    let mut x = 0u32;
    for i in 0..5 {
        let b = *bytes.get(i)?;
        x |= u32::from(b & 0x7f) << (7 * i);
        if b & 0x80 == 0 {
            return Some(if i == 4 && b > 0x0f {
                Err(postcard::Error::DeserializeBadVarint)
            } else {
                Ok((x, i + 1))
            });
        }
    }
    Some(Err(postcard::Error::DeserializeBadVarint))
}

/// Writes the header of the container whose payload follows `HEADER_LEN` placeholder bytes
/// in `out`.
#[cfg(test)]
fn seal(magic: &[u8; 8], version: u32, mut out: Vec<u8>) -> Vec<u8> {
    let (head, payload) = out.split_at_mut(HEADER_LEN);
    let crc = crc32fast::hash(payload);
    head.copy_from_slice(&header(magic, version, payload.len() as u64, crc));
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
    let (version, len, crc) = fields(header.try_into().expect("a header's length"));
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

/// A header's format version, payload length and payload CRC-32 (its tag unchecked).
pub(crate) fn fields(header: &[u8; HEADER_LEN]) -> (u32, u64, u32) {
    let field = |r: std::ops::Range<usize>| {
        header[r]
            .iter()
            .rev()
            .fold(0u64, |acc, &b| (acc << 8) | u64::from(b))
    };
    (field(8..12) as u32, field(12..20), field(20..24) as u32)
}

/// What [`read`] found.
pub(crate) enum Read {
    /// A container with the expected tag: the header and at most one byte more than the
    /// payload it announces.
    Container(Vec<u8>),
    /// A container with the expected tag whose header announces a payload of at least the
    /// bytes given to stream from: the header, and the file just past it
    /// ([`decode_streamed`]).
    Large([u8; HEADER_LEN], std::fs::File),
    /// Something else: its first bytes (at most a header's length) and the rest, unread.
    Other(Vec<u8>, std::fs::File),
}

/// Reads the file at `path` once (a pipe works): if it starts with `magic`, the header and as
/// many bytes as its header announces and one more (so [`split`] sees trailing bytes; a lying
/// header cannot make it read forever), or where it announces at least `stream_from` bytes
/// (if given) the header only ([`Read::Large`]); else only its first bytes (the rest is the
/// caller's).
pub(crate) fn read(
    path: &Path,
    magic: &[u8; 8],
    stream_from: Option<u64>,
) -> std::io::Result<Read> {
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
        if stream_from.is_some_and(|s| len >= s) {
            let header = bytes.try_into().expect("a header's length");
            return Ok(Read::Large(header, file));
        }
        // At most one byte beyond the announced payload: enough to see trailing bytes.
        file.take(len.saturating_add(1)).read_to_end(&mut bytes)?;
    }
    Ok(Read::Container(bytes))
}

/// Checks that `T`'s bulk decoding ([`Decode`]) of `payload` gives serde's value or serde's
/// error, in memory and streamed through buffers small enough to split values between two
/// reads; then the same of `payload` cut short and with a byte changed four ways, at places
/// through the whole of it. `name` names the payload in failures.
#[cfg(test)]
pub(crate) fn assert_decoded_as_serde<T>(payload: &[u8], name: &str)
where
    T: Decode + serde::de::DeserializeOwned + PartialEq,
{
    let check = |payload: &[u8], what: &str, capacities: &[usize]| {
        let want = decode_postcard::<T>(payload);
        assert!(decode_payload::<T>(payload) == want, "{what}");
        let crc = crc32fast::hash(payload);
        for &c in capacities {
            let got =
                decode_streamed_in::<T>(payload, payload.len() as u64, crc, c).map_err(
                    |e| match e {
                        Streamed::Content(words) => words,
                        e => panic!("{what}: an intact stream read as damaged: {e:?}"),
                    },
                );
            assert!(got == want, "{what}, streamed by {c}");
        }
    };
    check(payload, name, &[1 << 20, 4093, 7]);
    let n = payload.len();
    let places = (0..32.min(n)).chain((0..n).step_by(n / 31 + 1));
    for at in places {
        check(&payload[..at], &format!("{name} cut at {at}"), &[13]);
        for flip in [0x80u8, 0x7f, 0xff, 0x01] {
            let mut damaged = payload.to_vec();
            damaged[at] ^= flip;
            check(&damaged, &format!("{name}, byte {at} ^ {flip:#x}"), &[13]);
        }
    }
}

/// `bytes` decoded in memory (`in_memory`), after checking that a file of them decoded as it
/// is read (`streamed`, given the file's path) gives the same value or the same error.
#[cfg(test)]
pub(crate) fn read_both_ways<T: std::fmt::Debug, E: std::fmt::Debug>(
    bytes: &[u8],
    in_memory: impl FnOnce(&[u8], &Path) -> Result<T, E>,
    streamed: impl FnOnce(&Path) -> Result<T, E>,
) -> Result<T, E> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("file");
    std::fs::write(&path, bytes).unwrap();
    let in_memory = in_memory(bytes, &path);
    let streamed = streamed(&path);
    assert_eq!(
        format!("{streamed:?}"),
        format!("{in_memory:?}"),
        "decoded as read against in memory"
    );
    in_memory
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
        // Longer than the buffer it is written through, and a name longer than it.
        let values: Vec<f32> = (0..700_000u32).map(|i| i as f32 * 0.37 - 5.0).collect();
        let long_name = "n".repeat((1 << 20) + 17);
        let cases: [(&str, &[f32]); 4] = [
            ("empty", &[]),
            ("short", &values[..3]),
            ("long", &values),
            (&long_name, &values[..1000]),
        ];
        for (name, v) in cases {
            let payload = postcard::to_stdvec(&(name, v)).unwrap();
            let built = encode_postcard(&magic, 3, &(name, v)).unwrap();
            assert_eq!(built, encode(&magic, 3, &payload), "{name}");
            assert_eq!(&built[..8], &magic);
            assert_eq!(split(&built), Ok((3, &payload[..])), "{name}");
            assert_eq!(built.len(), built.capacity(), "{name}: sized exactly");
            // Written as it is encoded, after other bytes: the same bytes.
            let mut out = std::io::Cursor::new(vec![7u8; 40]);
            out.set_position(40);
            let out = write_postcard(out, &magic, 3, &(name, v)).unwrap();
            assert_eq!(
                out.position(),
                40 + built.len() as u64,
                "{name}: left at its end"
            );
            let written = out.into_inner();
            assert_eq!(written[..40], [7; 40], "{name}");
            assert_eq!(written[40..], built, "{name}: written as encoded");
        }
    }

    /// Regression: a disk that fills while a policy is written was reported as postcard's
    /// "The serialize buffer is full"; the writer's own error comes back (its kind and
    /// message).
    #[test]
    fn a_failed_write_keeps_its_error() {
        #[derive(Debug)]
        struct Full(std::io::Cursor<Vec<u8>>);
        impl std::io::Write for Full {
            fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
                if self.0.position() + buf.len() as u64 > 3 << 20 {
                    return Err(std::io::ErrorKind::StorageFull.into());
                }
                self.0.write(buf)
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        impl std::io::Seek for Full {
            fn seek(&mut self, to: std::io::SeekFrom) -> std::io::Result<u64> {
                self.0.seek(to)
            }
        }
        let values = vec![1.5f32; 2 << 20];
        let out = Full(std::io::Cursor::new(Vec::new()));
        let e = write_postcard(out, b"\x89TESTFQ\n", 1, &values).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::StorageFull);
    }
}
