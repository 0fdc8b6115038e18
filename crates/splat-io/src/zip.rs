//! The zip container of bundled PlayCanvas SOG files (`.sog`, [`crate::sog`]) and of PyTorch
//! checkpoints ([`crate::torch`]), as PKWARE's APPNOTE describes it: the end-of-central-directory
//! record (and Zip64's, which PyTorch's writer always adds), the central directory, and local
//! file headers. Entries stored (method 0) or deflated (method 8, through `flate2`) are read,
//! each checked against its CRC-32; stored entries are written. An archive is read through a
//! [`Source`]: memory, or a file read only where asked. Encryption and archives split over disks
//! are refused by name.

use flate2::Crc;
use std::borrow::Cow;
use std::cell::RefCell;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::Path;

/// The end-of-central-directory record's signature, and its size without the comment.
const END_SIGNATURE: u32 = 0x0605_4b50;
const END_SIZE: usize = 22;
/// A central directory entry's signature and fixed size.
const CENTRAL_SIGNATURE: u32 = 0x0201_4b50;
const CENTRAL_SIZE: usize = 46;
/// A local file header's signature and fixed size.
const LOCAL_SIGNATURE: u32 = 0x0403_4b50;
const LOCAL_SIZE: usize = 30;
/// Zip64's end-of-central-directory record (APPNOTE 4.3.14) and its locator (4.3.15), which
/// sits right before the classic record: signatures and fixed sizes.
const END64_SIGNATURE: u32 = 0x0606_4b50;
const END64_SIZE: usize = 56;
const LOCATOR_SIGNATURE: u32 = 0x0706_4b50;
const LOCATOR_SIZE: usize = 20;
/// The extra field holding an entry's Zip64 sizes and offset (APPNOTE 4.5.3).
const ZIP64_EXTRA: u16 = 0x0001;
/// Deflate's largest expansion (a 258-byte match per 2 bits, about 1032 : 1): an entry that
/// claims more than this times its compressed size is refused before it is inflated.
const DEFLATE_MAX_RATIO: u64 = 1032;
/// General-purpose flags: encrypted, and names in UTF-8.
const FLAG_ENCRYPTED: u16 = 0x1;
const FLAG_UTF8: u16 = 0x800;
/// "Version needed to extract": 2.0, deflate's.
const VERSION: u16 = 20;
/// DOS date of 1980-01-01 (the epoch of the format): written files carry no time, so the same
/// scene gives the same bytes.
const DOS_DATE: u16 = (1 << 5) | 1;

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(std::array::from_fn(|k| b[at + k]))
}

/// `len` bytes of `bytes` from `at`, or an error naming `what`.
fn slice<'a>(bytes: &'a [u8], at: usize, len: usize, what: &str) -> Result<&'a [u8], String> {
    at.checked_add(len)
        .and_then(|end| bytes.get(at..end))
        .ok_or_else(|| format!("zip: {what} runs past the end of the file ({} bytes)", bytes.len()))
}

/// Where an archive's bytes come from: memory (each piece borrowed), or a file, read piece by
/// piece, so that a reader that needs a few entries of a large archive reads only those.
pub(crate) trait Source {
    /// The archive's size in bytes.
    fn size(&self) -> u64;
    /// `len` bytes from `at`, or an error naming `what`.
    fn piece(&self, at: u64, len: u64, what: &str) -> Result<Cow<'_, [u8]>, String>;
}

impl Source for [u8] {
    fn size(&self) -> u64 {
        self.len() as u64
    }

    fn piece(&self, at: u64, len: u64, what: &str) -> Result<Cow<'_, [u8]>, String> {
        let (at, len) = (usize::try_from(at).unwrap_or(usize::MAX), usize::try_from(len).unwrap_or(usize::MAX));
        slice(self, at, len, what).map(Cow::Borrowed)
    }
}

/// An archive in a file, read where it is asked.
pub(crate) struct FileSource {
    file: RefCell<File>,
    size: u64,
}

impl FileSource {
    pub(crate) fn open(path: &Path) -> std::io::Result<Self> {
        let file = File::open(path)?;
        let size = file.metadata()?.len();
        Ok(Self { file: RefCell::new(file), size })
    }
}

impl Source for FileSource {
    fn size(&self) -> u64 {
        self.size
    }

    fn piece(&self, at: u64, len: u64, what: &str) -> Result<Cow<'_, [u8]>, String> {
        if at.checked_add(len).is_none_or(|end| end > self.size) {
            return Err(format!("zip: {what} runs past the end of the file ({} bytes)", self.size));
        }
        let mut piece = vec![0; to_usize(len)?];
        let mut file = self.file.borrow_mut();
        file.seek(SeekFrom::Start(at))
            .and_then(|_| file.read_exact(&mut piece))
            .map_err(|e| format!("zip: reading {what}: {e}"))?;
        Ok(Cow::Owned(piece))
    }
}

/// Every entry of the archive `bytes`, as (name, contents), in central-directory order.
pub(crate) fn read_entries(bytes: &[u8]) -> Result<Vec<(String, Vec<u8>)>, String> {
    let read = |(name, entry): (String, CentralEntry)| {
        let contents = entry.contents(bytes, &name)?.into_owned();
        Ok((name, contents))
    };
    directory(bytes)?.into_iter().map(read).collect()
}

/// The central directory of the archive `source`: each entry's name and where its contents
/// lie, in directory order (read them with [`CentralEntry::contents`]).
pub(crate) fn directory<S: Source + ?Sized>(source: &S) -> Result<Vec<(String, CentralEntry)>, String> {
    let end = find_end(source)?;
    let record = source.piece(end, END_SIZE as u64, "the end-of-central-directory record")?;
    let (mut disk, mut cd_disk) = (u32::from(u16_at(&record, 4)), u32::from(u16_at(&record, 6)));
    let (mut count, mut disk_count) = (u64::from(u16_at(&record, 10)), u64::from(u16_at(&record, 8)));
    let (mut cd_size, mut cd_offset) = (u64::from(u32_at(&record, 12)), u64::from(u32_at(&record, 16)));
    if let Some(record) = zip64_end(source, end)? {
        (disk, cd_disk) = (u32_at(&record, 16), u32_at(&record, 20));
        (disk_count, count) = (u64_at(&record, 24), u64_at(&record, 32));
        (cd_size, cd_offset) = (u64_at(&record, 40), u64_at(&record, 48));
    } else if count == u64::from(u16::MAX) || cd_size == u64::from(u32::MAX) || cd_offset == u64::from(u32::MAX) {
        return Err("zip: the end record points to Zip64's, which is missing (the file is damaged)".into());
    }
    if disk != 0 || cd_disk != 0 || disk_count != count {
        return Err("zip: an archive split over several disks".into());
    }
    let directory = source.piece(cd_offset, cd_size, "the central directory")?;
    // Each entry takes at least CENTRAL_SIZE bytes of the directory: a larger count is a lie.
    if count > (directory.len() / CENTRAL_SIZE) as u64 {
        return Err(format!("zip: {count} entries cannot fit a central directory of {} bytes", directory.len()));
    }
    let mut entries = Vec::with_capacity(count as usize);
    let mut at = 0;
    for index in 0..count {
        let head = slice(&directory, at, CENTRAL_SIZE, "a central directory entry")?;
        if u32_at(head, 0) != CENTRAL_SIGNATURE {
            return Err(format!("zip: central directory entry {index} has no signature"));
        }
        let (name_len, extra_len, comment_len) =
            (usize::from(u16_at(head, 28)), usize::from(u16_at(head, 30)), usize::from(u16_at(head, 32)));
        let name = slice(&directory, at + CENTRAL_SIZE, name_len, "an entry name")?;
        let name = String::from_utf8_lossy(name).into_owned();
        let extra = slice(&directory, at + CENTRAL_SIZE + name_len, extra_len, "an entry's extra fields")?;
        let mut entry = CentralEntry {
            flags: u16_at(head, 8),
            method: u16_at(head, 10),
            crc: u32_at(head, 16),
            compressed: u64::from(u32_at(head, 20)),
            size: u64::from(u32_at(head, 24)),
            offset: u64::from(u32_at(head, 42)),
        };
        entry.widen(extra, &name)?;
        entries.push((name, entry));
        at += CENTRAL_SIZE + name_len + extra_len + comment_len;
    }
    Ok(entries)
}

/// Zip64's end record, when the locator before the classic record at `end` says there is one.
fn zip64_end<S: Source + ?Sized>(source: &S, end: u64) -> Result<Option<Cow<'_, [u8]>>, String> {
    let Some(at) = end.checked_sub(LOCATOR_SIZE as u64) else { return Ok(None) };
    let locator = source.piece(at, LOCATOR_SIZE as u64, "Zip64's locator")?;
    if u32_at(&locator, 0) != LOCATOR_SIGNATURE {
        return Ok(None);
    }
    let record = source.piece(u64_at(&locator, 8), END64_SIZE as u64, "Zip64's end-of-central-directory record")?;
    if u32_at(&record, 0) != END64_SIGNATURE {
        return Err("zip: Zip64's end-of-central-directory record has no signature".into());
    }
    Ok(Some(record))
}

/// A Zip64 size or offset as an index into memory.
fn to_usize(v: u64) -> Result<usize, String> {
    usize::try_from(v).map_err(|_| format!("zip: an offset of {v} bytes does not fit this machine"))
}

/// The offset of the end-of-central-directory record: the last signature within the final
/// 22 + 65,535 bytes (the longest comment) whose comment length reaches the file's end.
fn find_end<S: Source + ?Sized>(source: &S) -> Result<u64, String> {
    let size = source.size();
    if size < END_SIZE as u64 {
        return Err(format!("zip: {size} bytes is too short for an archive"));
    }
    let first = size.saturating_sub((END_SIZE + usize::from(u16::MAX)) as u64);
    let tail = source.piece(first, size - first, "the end of the archive")?;
    (0..=tail.len() - END_SIZE)
        .rev()
        .find(|&at| {
            u32_at(&tail, at) == END_SIGNATURE && at + END_SIZE + usize::from(u16_at(&tail, at + 20)) == tail.len()
        })
        .map(|at| first + at as u64)
        .ok_or_else(|| "zip: no end-of-central-directory record (not a zip archive, or truncated)".into())
}

/// What the central directory says of one entry.
pub(crate) struct CentralEntry {
    flags: u16,
    method: u16,
    crc: u32,
    compressed: u64,
    size: u64,
    offset: u64,
}

impl CentralEntry {
    /// The sizes and offset that the classic fields mark as Zip64's (all ones), read from the
    /// Zip64 extra field, which holds those marked and only those, in this order (APPNOTE 4.5.3).
    fn widen(&mut self, mut extra: &[u8], name: &str) -> Result<(), String> {
        let marked = u64::from(u32::MAX);
        let wide = [self.size == marked, self.compressed == marked, self.offset == marked];
        if !wide.contains(&true) {
            return Ok(());
        }
        while extra.len() >= 4 {
            let (id, len) = (u16_at(extra, 0), usize::from(u16_at(extra, 2)));
            let body = slice(extra, 4, len, "an extra field")?;
            if id == ZIP64_EXTRA {
                let mut values = body.chunks_exact(8).map(|c| u64_at(c, 0));
                let mut next =
                    |what: &str| values.next().ok_or(format!("zip: entry {name}'s Zip64 field lacks its {what}"));
                if wide[0] {
                    self.size = next("size")?;
                }
                if wide[1] {
                    self.compressed = next("compressed size")?;
                }
                if wide[2] {
                    self.offset = next("offset")?;
                }
                return Ok(());
            }
            extra = &extra[4 + len..];
        }
        Err(format!("zip: entry {name} marks its sizes as Zip64's but has no Zip64 field"))
    }

    /// Where the entry's bytes (compressed, if it is) lie in the archive, after its local
    /// header.
    fn data<S: Source + ?Sized>(&self, source: &S, name: &str) -> Result<Range<u64>, String> {
        if self.flags & FLAG_ENCRYPTED != 0 {
            return Err(format!("zip: entry {name} is encrypted"));
        }
        let local = source.piece(self.offset, LOCAL_SIZE as u64, "a local file header")?;
        if u32_at(&local, 0) != LOCAL_SIGNATURE {
            return Err(format!("zip: entry {name} has no local file header at offset {}", self.offset));
        }
        let start =
            self.offset + (LOCAL_SIZE + usize::from(u16_at(&local, 26)) + usize::from(u16_at(&local, 28))) as u64;
        let end = start.checked_add(self.compressed).filter(|&end| end <= source.size());
        let end =
            end.ok_or_else(|| format!("zip: entry {name} runs past the end of the file ({} bytes)", source.size()))?;
        Ok(start..end)
    }

    /// A reader of the entry's contents a piece at a time ([`EntryReader`]): a stored entry's
    /// pieces are read from `source` where they lie; a compressed one is inflated (and checked)
    /// whole first.
    pub(crate) fn reader<'s, S: Source + ?Sized>(
        &self,
        source: &'s S,
        name: &str,
    ) -> Result<EntryReader<'s, S>, String> {
        let data = self.data(source, name)?;
        let stored = match self.method {
            0 if self.compressed == self.size => {
                Stored { source, name: name.to_string(), data, hashed: 0, crc: Crc::new(), expected: self.crc }
            }
            0 => return Err(format!("zip: stored entry {name} has {} bytes, but says {}", self.compressed, self.size)),
            _ => return Ok(EntryReader::Inflated(self.contents(source, name)?.into_owned())),
        };
        Ok(EntryReader::Stored(stored))
    }

    /// The entry's contents, inflated and checked against its CRC-32: a stored entry of an
    /// archive in memory is borrowed from it.
    pub(crate) fn contents<'s, S: Source + ?Sized>(&self, source: &'s S, name: &str) -> Result<Cow<'s, [u8]>, String> {
        let range = self.data(source, name)?;
        let data = source.piece(range.start, range.end - range.start, &format!("entry {name}"))?;
        let contents = match self.method {
            0 if self.compressed == self.size => data,
            0 => return Err(format!("zip: stored entry {name} has {} bytes, but says {}", self.compressed, self.size)),
            8 => {
                if self.size > DEFLATE_MAX_RATIO.saturating_mul(self.compressed).saturating_add(1024) {
                    return Err(format!(
                        "zip: entry {name} claims {} bytes from {}, more than deflate can expand",
                        self.size, self.compressed
                    ));
                }
                let mut out = Vec::with_capacity(to_usize(self.size)?);
                flate2::read::DeflateDecoder::new(&data[..])
                    .take(self.size + 1)
                    .read_to_end(&mut out)
                    .map_err(|e| format!("zip: entry {name}: {e}"))?;
                if out.len() as u64 != self.size {
                    return Err(format!("zip: entry {name} inflates to {} bytes, but says {}", out.len(), self.size));
                }
                Cow::Owned(out)
            }
            method => {
                return Err(format!("zip: entry {name} uses compression method {method} (only 0 and 8 are read)"));
            }
        };
        let mut crc = Crc::new();
        crc.update(&contents);
        check_crc(&crc, self.crc, name)?;
        Ok(contents)
    }
}

/// An error unless `crc` (of an entry's contents) is the CRC-32 the directory gives it.
fn check_crc(crc: &Crc, expected: u32, name: &str) -> Result<(), String> {
    if crc.sum() != expected {
        return Err(format!("zip: entry {name} fails its CRC-32 check (the file is damaged)"));
    }
    Ok(())
}

/// The largest piece of an entry read at once where no piece asked for needs it (to hash it).
const PIECE: u64 = 1 << 24;

/// An entry's contents read a piece at a time, in order. A stored entry's pieces are read from
/// the archive where they lie and every byte of it is hashed once, those between and after the
/// pieces asked for too, so that [`EntryReader::finish`] checks its CRC-32 without the entry
/// ever being held whole; a compressed entry is inflated and checked whole when it is opened.
pub(crate) enum EntryReader<'s, S: Source + ?Sized> {
    Stored(Stored<'s, S>),
    Inflated(Vec<u8>),
}

/// A stored entry being read: where its bytes lie, and the hash of those before `hashed`.
pub(crate) struct Stored<'s, S: Source + ?Sized> {
    source: &'s S,
    name: String,
    data: Range<u64>,
    hashed: u64,
    crc: Crc,
    expected: u32,
}

impl<S: Source + ?Sized> EntryReader<'_, S> {
    /// The entry's size in bytes.
    pub(crate) fn len(&self) -> u64 {
        match self {
            Self::Stored(s) => s.data.end - s.data.start,
            Self::Inflated(bytes) => bytes.len() as u64,
        }
    }

    /// Bytes `at..at + len` of the entry (within [`EntryReader::len`]), `at` no earlier than
    /// the last piece's end.
    pub(crate) fn piece(&mut self, at: u64, len: u64) -> Result<Cow<'_, [u8]>, String> {
        match self {
            Self::Stored(s) => {
                while s.hashed < at {
                    let gap = (at - s.hashed).min(PIECE);
                    s.crc.update(&s.source.piece(s.data.start + s.hashed, gap, &s.name)?);
                    s.hashed += gap;
                }
                let piece = s.source.piece(s.data.start + at, len, &s.name)?;
                s.crc.update(&piece);
                s.hashed = at + len;
                Ok(piece)
            }
            Self::Inflated(bytes) => Ok(Cow::Borrowed(&bytes[at as usize..(at + len) as usize])),
        }
    }

    /// Hash the rest of a stored entry and check its CRC-32.
    pub(crate) fn finish(&mut self) -> Result<(), String> {
        let end = self.len();
        self.piece(end, 0)?;
        match self {
            Self::Stored(s) => check_crc(&s.crc, s.expected, &s.name),
            Self::Inflated(_) => Ok(()),
        }
    }
}

/// An archive of `entries` (name, contents), each stored uncompressed (WebP is compressed
/// already), in the given order.
pub(crate) fn write_stored(entries: &[(&str, &[u8])]) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    let mut directory = Vec::new();
    for (name, data) in entries {
        let (size, offset) = (u32_len(data.len(), name)?, u32_len(out.len(), name)?);
        let name_len = u16::try_from(name.len()).map_err(|_| format!("zip: entry name {name} is too long"))?;
        let mut crc = Crc::new();
        crc.update(data);
        // The fields shared by the local header (from "version needed") and the central entry.
        let mut common = Vec::with_capacity(26);
        for v in [VERSION, FLAG_UTF8, 0, 0, DOS_DATE] {
            common.extend_from_slice(&v.to_le_bytes());
        }
        for v in [crc.sum(), size, size] {
            common.extend_from_slice(&v.to_le_bytes());
        }
        common.extend_from_slice(&name_len.to_le_bytes());
        common.extend_from_slice(&0u16.to_le_bytes());
        out.extend_from_slice(&LOCAL_SIGNATURE.to_le_bytes());
        out.extend_from_slice(&common);
        out.extend_from_slice(name.as_bytes());
        out.extend_from_slice(data);
        directory.extend_from_slice(&CENTRAL_SIGNATURE.to_le_bytes());
        directory.extend_from_slice(&VERSION.to_le_bytes());
        directory.extend_from_slice(&common);
        // Comment length, disk, internal and external attributes, local header offset.
        for v in [0u16, 0, 0] {
            directory.extend_from_slice(&v.to_le_bytes());
        }
        directory.extend_from_slice(&0u32.to_le_bytes());
        directory.extend_from_slice(&offset.to_le_bytes());
        directory.extend_from_slice(name.as_bytes());
    }
    let count = u16::try_from(entries.len()).map_err(|_| "zip: more than 65,535 entries".to_string())?;
    let (cd_size, cd_offset) = (u32_len(directory.len(), "the directory")?, u32_len(out.len(), "the directory")?);
    out.extend_from_slice(&directory);
    out.extend_from_slice(&END_SIGNATURE.to_le_bytes());
    for v in [0u16, 0, count, count] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&cd_size.to_le_bytes());
    out.extend_from_slice(&cd_offset.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    Ok(out)
}

fn u32_len(len: usize, what: &str) -> Result<u32, String> {
    u32::try_from(len).map_err(|_| format!("zip: {what} passes 4 GiB, which needs zip64"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CPython's zipfile with its Zip64 limits set to zero (`zipfile.ZIP64_LIMIT = 0`,
    /// `ZIP_FILECOUNT_LIMIT = 0`), so that it writes Zip64's end record and locator, and the
    /// sizes and an offset in Zip64 extra fields, as PyTorch's writer does: two stored entries.
    #[test]
    fn zip64_archives_read() {
        let hex = "504b03042d00000000005d33865d86a61036ffffffffffffffff0c0014006172632f646174612e706b6c010010000500000000000000050000000000000068656c6c6f504b03042d00000000005d33865d46d76c45ffffffffffffffff0a0014006172632f646174612f30010010000a000000000000000a0000000000000000010203040506070809504b01022d032d00000000005d33865d86a61036ffffffffffffffff0c00140000000000000000008001000000006172632f646174612e706b6c0100100005000000000000000500000000000000504b01022d032d00000000005d33865d46d76c45ffffffffffffffff0a001c0000000000000000008001ffffffff6172632f646174612f30010018000a000000000000000a000000000000004300000000000000504b06062c000000000000002d002d00000000000000000002000000000000000200000000000000a2000000000000008900000000000000504b0607000000002b0100000000000001000000504b05060000000002000200a2000000890000000000";
        let zip: Vec<u8> = (0..hex.len()).step_by(2).map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap()).collect();
        let entries = read_entries(&zip).unwrap();
        let expected = [("arc/data.pkl".to_string(), b"hello".to_vec()), ("arc/data/0".to_string(), (0..10).collect())];
        assert_eq!(entries, expected);
        // Zip64's record damaged: refused by name, not read through the classic one.
        let mut damaged = zip.clone();
        damaged[0x12b] ^= 0xff; // its signature
        assert!(read_entries(&damaged).unwrap_err().contains("Zip64"), "{:?}", read_entries(&damaged));
        for len in 0..zip.len() {
            assert!(read_entries(&zip[..len]).is_err(), "{len} bytes");
        }
    }

    #[test]
    fn stored_entries_read_back() {
        let zip = write_stored(&[("meta.json", b"{}"), ("a.webp", &[1, 2, 3])]).unwrap();
        let entries = read_entries(&zip).unwrap();
        assert_eq!(entries, vec![("meta.json".to_string(), b"{}".to_vec()), ("a.webp".to_string(), vec![1, 2, 3])]);
    }

    #[test]
    fn damage_is_named() {
        let mut zip = write_stored(&[("a.webp", &[1, 2, 3])]).unwrap();
        let data = LOCAL_SIZE + "a.webp".len();
        zip[data] ^= 0xff;
        assert!(read_entries(&zip).unwrap_err().contains("CRC-32"));
        assert!(read_entries(&zip[..zip.len() - 1]).unwrap_err().contains("end-of-central-directory"));
        assert!(read_entries(b"not a zip archive at all, long enough").is_err());
    }

    /// A deflated entry (written by flate2 into a hand-made archive) inflates and checks.
    #[test]
    fn deflated_entries_inflate() {
        use std::io::Write;
        let contents = b"SOG SOG SOG SOG SOG SOG SOG SOG".repeat(20);
        let mut encoder = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::default());
        encoder.write_all(&contents).unwrap();
        let deflated = encoder.finish().unwrap();
        let mut zip = write_stored(&[("x", &deflated)]).unwrap();
        // Method 8 and the inflated size and CRC, in the local header and the central entry.
        let mut crc = Crc::new();
        crc.update(&contents);
        let central = zip.len() - END_SIZE - (CENTRAL_SIZE + 1);
        for (header, method) in [(0, 8), (central, 10)] {
            zip[header + method..header + method + 2].copy_from_slice(&8u16.to_le_bytes());
            let fields = header + method + 6;
            zip[fields..fields + 4].copy_from_slice(&crc.sum().to_le_bytes());
            zip[fields + 8..fields + 12].copy_from_slice(&(contents.len() as u32).to_le_bytes());
        }
        assert_eq!(read_entries(&zip).unwrap(), vec![("x".to_string(), contents)]);
    }
}
