//! The other layout the cache file was measured against (DESIGN.md §5, persistence): one
//! monolithic snapshot, every base triangle's record in one file written whole at each save
//! (a temporary file, fsync, rename over the old one, fsync of the directory), with a BLAKE3
//! checksum a load verifies. The records are the store's own bytes (`encoded_records`), so the
//! two differ only in how they reach the disk and come back.

use std::io::Write as _;
use std::path::Path;

use anyhow::{Context, bail};

const MAGIC: &[u8; 8] = b"WTSNAP01";
const CHECKSUM_BYTES: usize = 32;

/// Writes `records` as one snapshot at `path`, crash-safe: the old file stays whole until the
/// rename, and the rename is durable once the directory is synced. Returns the bytes written.
pub fn save(path: &Path, records: &[(u32, Vec<u8>)]) -> anyhow::Result<u64> {
    let size = records.iter().map(|(_, r)| 8 + r.len()).sum::<usize>();
    let mut bytes = Vec::with_capacity(MAGIC.len() + 4 + size + CHECKSUM_BYTES);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&(records.len() as u32).to_le_bytes());
    for (base, record) in records {
        bytes.extend_from_slice(&base.to_le_bytes());
        bytes.extend_from_slice(&(record.len() as u32).to_le_bytes());
        bytes.extend_from_slice(record);
    }
    let checksum = blake3::hash(&bytes);
    bytes.extend_from_slice(checksum.as_bytes());
    let temporary = path.with_extension("tmp");
    {
        let mut file = std::fs::File::create(&temporary)?;
        file.write_all(&bytes)?;
        file.sync_all()?;
    }
    std::fs::rename(&temporary, path)?;
    let dir = path.parent().context("a snapshot has a directory")?;
    std::fs::File::open(dir)?.sync_all()?;
    Ok(bytes.len() as u64)
}

/// Reads a snapshot back, its checksum verified: the records, encoded.
pub fn load(path: &Path) -> anyhow::Result<Vec<(u32, Vec<u8>)>> {
    let bytes = std::fs::read(path)?;
    if bytes.len() < MAGIC.len() + 4 + CHECKSUM_BYTES || !bytes.starts_with(MAGIC) {
        bail!("not a snapshot");
    }
    let (body, checksum) = bytes.split_at(bytes.len() - CHECKSUM_BYTES);
    if blake3::hash(body).as_bytes() != checksum {
        bail!("its checksum does not match");
    }
    let word = |at: usize| -> anyhow::Result<u32> {
        let b = body.get(at..at + 4).context("truncated")?;
        Ok(u32::from_le_bytes(b.try_into()?))
    };
    let count = word(MAGIC.len())? as usize;
    let mut at = MAGIC.len() + 4;
    let mut records = Vec::with_capacity(count);
    for _ in 0..count {
        let (base, len) = (word(at)?, word(at + 4)? as usize);
        let record = body.get(at + 8..at + 8 + len).context("truncated")?;
        records.push((base, record.to_vec()));
        at += 8 + len;
    }
    Ok(records)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_snapshot_comes_back_and_a_damaged_one_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("snapshot.bin");
        let records = vec![(3, vec![1, 2, 3]), (9, Vec::new()), (12, vec![7; 300])];
        save(&path, &records).unwrap();
        assert_eq!(load(&path).unwrap(), records);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[20] ^= 1;
        std::fs::write(&path, &bytes).unwrap();
        assert!(load(&path).is_err());
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
        assert!(load(&path).is_err());
    }
}
