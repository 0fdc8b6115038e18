//! The zip container of bundled PlayCanvas SOG files (`.sog`, [`crate::sog`]), as PKWARE's
//! APPNOTE describes it: the end-of-central-directory record, the central directory, and
//! local file headers. Entries stored (method 0) or deflated (method 8, through `flate2`) are
//! read, each checked against its CRC-32; stored entries are written. Zip64, encryption and
//! archives split over disks are refused by name: a SOG bundle needs none of them.

use flate2::Crc;
use std::io::Read;

/// The end-of-central-directory record's signature, and its size without the comment.
const END_SIGNATURE: u32 = 0x0605_4b50;
const END_SIZE: usize = 22;
/// A central directory entry's signature and fixed size.
const CENTRAL_SIGNATURE: u32 = 0x0201_4b50;
const CENTRAL_SIZE: usize = 46;
/// A local file header's signature and fixed size.
const LOCAL_SIGNATURE: u32 = 0x0403_4b50;
const LOCAL_SIZE: usize = 30;
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

/// `len` bytes of `bytes` from `at`, or an error naming `what`.
fn slice<'a>(bytes: &'a [u8], at: usize, len: usize, what: &str) -> Result<&'a [u8], String> {
    at.checked_add(len)
        .and_then(|end| bytes.get(at..end))
        .ok_or_else(|| format!("zip: {what} runs past the end of the file ({} bytes)", bytes.len()))
}

/// Every entry of the archive `bytes`, as (name, contents), in central-directory order.
pub(crate) fn read_entries(bytes: &[u8]) -> Result<Vec<(String, Vec<u8>)>, String> {
    let end = find_end(bytes)?;
    let record = &bytes[end..end + END_SIZE];
    let (disk, cd_disk) = (u16_at(record, 4), u16_at(record, 6));
    let (count, cd_size, cd_offset) = (u16_at(record, 10), u32_at(record, 12), u32_at(record, 16));
    if count == u16::MAX || cd_size == u32::MAX || cd_offset == u32::MAX {
        return Err("zip: a zip64 archive (more than 65,535 entries or 4 GiB), which a SOG bundle never needs".into());
    }
    if disk != 0 || cd_disk != 0 || u16_at(record, 8) != count {
        return Err("zip: an archive split over several disks".into());
    }
    let directory = slice(bytes, cd_offset as usize, cd_size as usize, "the central directory")?;
    let mut entries = Vec::with_capacity(usize::from(count));
    let mut at = 0;
    for index in 0..count {
        let head = slice(directory, at, CENTRAL_SIZE, "a central directory entry")?;
        if u32_at(head, 0) != CENTRAL_SIGNATURE {
            return Err(format!("zip: central directory entry {index} has no signature"));
        }
        let (name_len, extra_len, comment_len) =
            (usize::from(u16_at(head, 28)), usize::from(u16_at(head, 30)), usize::from(u16_at(head, 32)));
        let name = slice(directory, at + CENTRAL_SIZE, name_len, "an entry name")?;
        let name = String::from_utf8_lossy(name).into_owned();
        let entry = CentralEntry {
            flags: u16_at(head, 8),
            method: u16_at(head, 10),
            crc: u32_at(head, 16),
            compressed: u32_at(head, 20),
            size: u32_at(head, 24),
            offset: u32_at(head, 42),
        };
        entries.push((name.clone(), entry.contents(bytes, &name)?));
        at += CENTRAL_SIZE + name_len + extra_len + comment_len;
    }
    Ok(entries)
}

/// The offset of the end-of-central-directory record: the last signature within the final
/// 22 + 65,535 bytes (the longest comment) whose comment length reaches the file's end.
fn find_end(bytes: &[u8]) -> Result<usize, String> {
    if bytes.len() < END_SIZE {
        return Err(format!("zip: {} bytes is too short for an archive", bytes.len()));
    }
    let first = bytes.len().saturating_sub(END_SIZE + usize::from(u16::MAX));
    (first..=bytes.len() - END_SIZE)
        .rev()
        .find(|&at| {
            u32_at(bytes, at) == END_SIGNATURE && at + END_SIZE + usize::from(u16_at(bytes, at + 20)) == bytes.len()
        })
        .ok_or_else(|| "zip: no end-of-central-directory record (not a zip archive, or truncated)".into())
}

/// What the central directory says of one entry.
struct CentralEntry {
    flags: u16,
    method: u16,
    crc: u32,
    compressed: u32,
    size: u32,
    offset: u32,
}

impl CentralEntry {
    /// The entry's contents, inflated and checked against its CRC-32.
    fn contents(&self, bytes: &[u8], name: &str) -> Result<Vec<u8>, String> {
        if self.flags & FLAG_ENCRYPTED != 0 {
            return Err(format!("zip: entry {name} is encrypted"));
        }
        let local = slice(bytes, self.offset as usize, LOCAL_SIZE, "a local file header")?;
        if u32_at(local, 0) != LOCAL_SIGNATURE {
            return Err(format!("zip: entry {name} has no local file header at offset {}", self.offset));
        }
        let start = self.offset as usize + LOCAL_SIZE + usize::from(u16_at(local, 26)) + usize::from(u16_at(local, 28));
        let data = slice(bytes, start, self.compressed as usize, &format!("entry {name}"))?;
        let contents = match self.method {
            0 if self.compressed == self.size => data.to_vec(),
            0 => return Err(format!("zip: stored entry {name} has {} bytes, but says {}", self.compressed, self.size)),
            8 => {
                if u64::from(self.size) > DEFLATE_MAX_RATIO * u64::from(self.compressed) + 1024 {
                    return Err(format!(
                        "zip: entry {name} claims {} bytes from {}, more than deflate can expand",
                        self.size, self.compressed
                    ));
                }
                let mut out = Vec::with_capacity(self.size as usize);
                flate2::read::DeflateDecoder::new(data)
                    .take(u64::from(self.size) + 1)
                    .read_to_end(&mut out)
                    .map_err(|e| format!("zip: entry {name}: {e}"))?;
                if out.len() != self.size as usize {
                    return Err(format!("zip: entry {name} inflates to {} bytes, but says {}", out.len(), self.size));
                }
                out
            }
            method => {
                return Err(format!("zip: entry {name} uses compression method {method} (only 0 and 8 are read)"));
            }
        };
        let mut crc = Crc::new();
        crc.update(&contents);
        if crc.sum() != self.crc {
            return Err(format!("zip: entry {name} fails its CRC-32 check (the file is damaged)"));
        }
        Ok(contents)
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
