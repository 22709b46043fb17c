//! The redb file under a cache file (DESIGN.md §5): opening it, refusing one that is not this
//! SMA's, listing the base triangles it holds records of, reading records as they are wanted,
//! and one write transaction per commit. redb is crash-safe by
//! design (copy-on-write pages, a checksummed commit slot), so a kill during a commit leaves the
//! previous commit; a file altered outside redb fails its integrity check on open.

use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};

use redb::{
    Database, DatabaseError, ReadableDatabase, ReadableTable, StorageError, TableDefinition,
};

use super::key::{FORMAT_VERSION, StoreKey};
use super::record::BaseRecord;

/// The key record: the format version, then the key (`key::StoreKey`).
const META: TableDefinition<&str, &[u8]> = TableDefinition::new("meta");
const FORMAT: &str = "format";
const KEY: &str = "key";
/// One record per base triangle, keyed by its index, postcard-encoded (`record::BaseRecord`).
const BASES: TableDefinition<u32, &[u8]> = TableDefinition::new("bases");

/// redb's page cache: the file is read once at start and written in commits, so a small one.
const PAGE_CACHE_BYTES: usize = 64 << 20;

/// Why a store is not used.
#[derive(Debug)]
pub enum Unusable {
    /// Its content is not this SMA's: truncated, corrupt or foreign. It is set aside and the SMA
    /// starts empty.
    Refused(String),
    /// It cannot be used now (locked by another SMA, an unwritable directory): the SMA carries
    /// on without it and leaves it as it is.
    Fault(String),
}

/// An open store and the base triangles it holds records of, ascending.
pub struct Opened {
    pub db: Database,
    pub stored: Vec<u32>,
}

/// Opens the store at `path` for `key`: a new or empty file becomes an empty store with the key
/// written; an existing one must pass redb's integrity check and hold this key. Its records are
/// read later, when wanted ([`read_records`]).
pub fn open(path: &Path, key: &StoreKey) -> Result<Opened, Unusable> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| {
            Unusable::Fault(format!(
                "its directory {} cannot be made: {e}",
                dir.display()
            ))
        })?;
    }
    let existed = std::fs::metadata(path).is_ok_and(|m| m.len() > 0);
    // A plain open trusts the file and may panic on one altered outside redb; the integrity
    // check reads it whole, which loading at start does anyway. The panic guard is for what
    // the check misses: a corrupt file is refused, never the end of the SMA.
    let opened = std::panic::catch_unwind(|| {
        Database::builder()
            .set_cache_size(PAGE_CACHE_BYTES)
            .set_check_integrity_on_open(existed)
            .create(path)
    })
    .map_err(|_| Unusable::Refused("it is corrupt (the store could not read it)".into()))?;
    let db = opened.map_err(open_error)?;
    if !existed {
        write_key(&db, key).map_err(|e| Unusable::Fault(format!("it cannot be written: {e}")))?;
        return Ok(Opened {
            db,
            stored: Vec::new(),
        });
    }
    let stored = std::panic::catch_unwind(AssertUnwindSafe(|| read_index(&db, key)))
        .map_err(|_| Unusable::Refused("it is corrupt (reading it failed)".into()))??;
    Ok(Opened { db, stored })
}

fn open_error(e: DatabaseError) -> Unusable {
    match e {
        DatabaseError::DatabaseAlreadyOpen | DatabaseError::LockProtocolMismatch => {
            Unusable::Fault("another SMA has it open".into())
        }
        DatabaseError::Storage(StorageError::Io(io))
            if matches!(
                io.kind(),
                std::io::ErrorKind::PermissionDenied | std::io::ErrorKind::ReadOnlyFilesystem
            ) =>
        {
            Unusable::Fault(format!("it cannot be opened for writing: {io}"))
        }
        DatabaseError::Storage(StorageError::Io(io)) => {
            Unusable::Refused(format!("it is truncated or not a store ({io})"))
        }
        other => Unusable::Refused(format!("it is not a readable store ({other})")),
    }
}

fn write_key(db: &Database, key: &StoreKey) -> Result<(), redb::Error> {
    let txn = db.begin_write()?;
    {
        let mut meta = txn.open_table(META)?;
        meta.insert(FORMAT, FORMAT_VERSION.to_le_bytes().as_slice())?;
        let key = postcard::to_stdvec(key).expect("a key encodes");
        meta.insert(KEY, key.as_slice())?;
        txn.open_table(BASES)?;
    }
    txn.commit()?;
    Ok(())
}

/// Checks the key record and lists the base triangles with a record.
fn read_index(db: &Database, key: &StoreKey) -> Result<Vec<u32>, Unusable> {
    let unreadable =
        |e: &dyn std::fmt::Display| Unusable::Refused(format!("reading it failed: {e}"));
    let txn = db.begin_read().map_err(|e| unreadable(&e))?;
    let meta = txn
        .open_table(META)
        .map_err(|_| Unusable::Refused("it holds no key record (not a cache file)".into()))?;
    let format = meta.get(FORMAT).map_err(|e| unreadable(&e))?;
    let format = format
        .and_then(|f| <[u8; 4]>::try_from(f.value()).ok())
        .map(u32::from_le_bytes)
        .ok_or_else(|| Unusable::Refused("its key record has no format version".into()))?;
    if format != FORMAT_VERSION {
        return Err(Unusable::Refused(format!(
            "it has format version {format}, this SMA reads version {FORMAT_VERSION}"
        )));
    }
    let stored: StoreKey = meta
        .get(KEY)
        .map_err(|e| unreadable(&e))?
        .and_then(|k| postcard::from_bytes(k.value()).ok())
        .ok_or_else(|| Unusable::Refused("its key record does not decode".into()))?;
    if let Some(reason) = key.mismatch(&stored) {
        return Err(Unusable::Refused(reason));
    }
    let bases = txn.open_table(BASES).map_err(|e| unreadable(&e))?;
    let keys = bases.iter().map_err(|e| unreadable(&e))?;
    keys.map(|entry| entry.map(|(base, _)| base.value()))
        .collect::<Result<_, _>>()
        .map_err(|e| unreadable(&e))
}

/// A base triangle's record as read: decoded, or why not.
pub type ReadRecord = (u32, Result<BaseRecord, String>);

/// The records of `bases`, in one read transaction (the writer's commits go on beside it):
/// each decoded, or why not. Those the file does not hold are left out.
pub fn read_records(db: &Database, bases: &[u32]) -> Result<Vec<ReadRecord>, String> {
    let read = || -> Result<_, redb::Error> {
        let txn = db.begin_read()?;
        let table = txn.open_table(BASES)?;
        let mut records = Vec::with_capacity(bases.len());
        for &base in bases {
            if let Some(bytes) = table.get(base)? {
                let record = postcard::from_bytes(bytes.value()).map_err(|e| {
                    format!("the record of base triangle {base} does not decode ({e})")
                });
                records.push((base, record));
            }
        }
        Ok(records)
    };
    std::panic::catch_unwind(AssertUnwindSafe(read))
        .map_err(|_| "the store could not read it".to_string())?
        .map_err(|e| e.to_string())
}

/// Where a refused store is moved: `PATH.rejected`.
pub fn rejected_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".rejected");
    PathBuf::from(name)
}

/// One commit: each base triangle's encoded record, or None where the record is gone (the
/// subtree is the bare base triangle again, without samples).
pub fn commit(db: &Database, records: &[(u32, Option<Vec<u8>>)]) -> Result<(), redb::Error> {
    let txn = db.begin_write()?;
    {
        let mut bases = txn.open_table(BASES)?;
        for (base, bytes) in records {
            match bytes {
                Some(bytes) => {
                    bases.insert(base, bytes.as_slice())?;
                }
                None => {
                    bases.remove(base)?;
                }
            }
        }
    }
    txn.commit()?;
    Ok(())
}
