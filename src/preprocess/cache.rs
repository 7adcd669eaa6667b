//! On-disk cache of preprocessing results, keyed by a hash of everything they depend on.
//!
//! File layout: magic `TRLCACHE`, format version (u32), key (u64), payload length (u64),
//! payload checksum (u64, FNV-1a), payload (bincode). A file whose magic, version, key, length
//! or checksum does not match is reported as stale or corrupt and rebuilt, never trusted.
//! Files are written to a temporary name and renamed, so an interrupted write leaves nothing
//! under the final name.

use super::settings::Settings;
use crate::numeric::hash::Fnv;
use crate::physics::Material;
use crate::scene::mesh::Mesh;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"TRLCACHE";
/// Bump whenever the preprocessing's results change for the same inputs.
pub const FORMAT_VERSION: u32 = 18;

/// Key of a preprocessing run: mesh geometry, material, settings and format version.
pub fn key(mesh: &Mesh, material: &Material, settings: &Settings) -> u64 {
    let mut h = Fnv::default();
    h.write(&FORMAT_VERSION.to_le_bytes());
    h.write(bytemuck::cast_slice(&mesh.positions));
    h.write(bytemuck::cast_slice(&mesh.normals));
    h.write(bytemuck::cast_slice(&mesh.indices));
    for v in material
        .sigma_s_prime
        .iter()
        .chain(&material.sigma_a)
        .chain([&material.eta])
    {
        h.write(&v.to_le_bytes());
    }
    h.write(material.model.name().as_bytes());
    h.write(&crate::physics::profile::tables_hash().to_le_bytes());
    h.write(&bincode::serialize(settings).unwrap_or_default());
    h.finish()
}

/// Default cache folder: `$XDG_CACHE_HOME/translucent`, else `$HOME/.cache/translucent`.
pub fn default_dir() -> PathBuf {
    if let Some(x) = std::env::var_os("XDG_CACHE_HOME").filter(|x| !x.is_empty()) {
        return PathBuf::from(x).join("translucent");
    }
    match std::env::var_os("HOME").filter(|x| !x.is_empty()) {
        Some(h) => PathBuf::from(h).join(".cache").join("translucent"),
        None => PathBuf::from(".translucent-cache"),
    }
}

/// Path of the cache file for `key` in `dir`.
pub fn path(dir: &Path, key: u64) -> PathBuf {
    dir.join(format!("{key:016x}.bin"))
}

/// Writes `value` (a preprocessing, or another result keyed like one) under `key`.
pub fn store<T: serde::Serialize>(dir: &Path, key: u64, value: &T) -> Result<PathBuf> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create cache folder '{}'", dir.display()))?;
    let payload = bincode::serialize(value).context("cannot serialise the preprocessing")?;
    let mut sum = Fnv::default();
    sum.write(&payload);
    let mut bytes = Vec::with_capacity(payload.len() + 36);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes.extend_from_slice(&key.to_le_bytes());
    bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&sum.finish().to_le_bytes());
    bytes.extend_from_slice(&payload);
    let target = path(dir, key);
    crate::output::write_atomic(&target, |tmp| Ok(std::fs::write(tmp, &bytes)?))?;
    Ok(target)
}

/// Loads the entry for `key`: `Ok(None)` if there is none, an error naming the problem if
/// the file is stale or corrupt. Temporaries that killed runs left in the folder go first: a
/// run that only reads the cache cleans it too.
pub fn load<T: serde::de::DeserializeOwned>(dir: &Path, key: u64) -> Result<Option<T>> {
    crate::output::remove_stale_temporaries(dir);
    let p = path(dir, key);
    match std::fs::metadata(&p) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        _ => {}
    }
    let bytes = crate::input::read_regular(&p, crate::input::MAX_DATA_BYTES, "cache file")?;
    if bytes.len() < 36 || &bytes[..8] != MAGIC {
        bail!(
            "cache file '{}' is not a translucent cache file",
            p.display()
        );
    }
    let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap_or_default());
    let u64_at = |i: usize| u64::from_le_bytes(bytes[i..i + 8].try_into().unwrap_or_default());
    let version = u32_at(8);
    if version != FORMAT_VERSION {
        bail!(
            "cache file '{}' has format version {version}, this build writes {FORMAT_VERSION}",
            p.display()
        );
    }
    if u64_at(12) != key {
        bail!("cache file '{}' belongs to different inputs", p.display());
    }
    let len = u64_at(20) as usize;
    let payload = &bytes[36..];
    if payload.len() != len {
        bail!(
            "cache file '{}' is truncated ({} of {len} bytes)",
            p.display(),
            payload.len()
        );
    }
    let mut sum = Fnv::default();
    sum.write(payload);
    if sum.finish() != u64_at(28) {
        bail!(
            "cache file '{}' is corrupt (checksum mismatch)",
            p.display()
        );
    }
    let value = bincode::deserialize(payload)
        .with_context(|| format!("cache file '{}' cannot be decoded", p.display()))?;
    Ok(Some(value))
}
