//! Reading input files safely: regular files only (a FIFO would block forever, `/dev/zero`
//! would be read until the kernel kills the process), and no more than a stated size.

use anyhow::{bail, Context, Result};
use std::io::Read;
use std::path::Path;

/// Largest scene file: a scene is a few hundred bytes of TOML.
pub const MAX_SCENE_BYTES: u64 = 1 << 20;

/// Largest OBJ file: 4 M triangles (`scene::MAX_TRIANGLES`) with their vertices, texture
/// coordinates and normals as text fit well within it.
pub const MAX_OBJ_BYTES: u64 = 1 << 30;

/// Largest texture file (compressed PNG or JPEG).
pub const MAX_TEXTURE_BYTES: u64 = 256 << 20;

/// Largest cache or EXR file read back.
pub const MAX_DATA_BYTES: u64 = 8 << 30;

/// Widest and tallest image read back or written, pixels per side: the largest 2D image of
/// common devices.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// The machine's memory, bytes (`MemTotal` of /proc/meminfo; 16 GiB where it cannot be read):
/// what an input may make the program allocate is bounded by a part of it.
pub fn host_memory_bytes() -> u64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| {
            let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
            let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
            Some(kib * 1024)
        })
        .unwrap_or(16 << 30)
}

/// Refuses an image whose header declares more than `most_w` x `most_h` pixels, before its
/// decoder allocates what the header claims (a few hundred bytes can ask for 24 GiB): "its
/// header declares W x H pixels: at most ... are read".
pub fn check_declared_size(w: u64, h: u64, most_w: u64, most_h: u64) -> Result<()> {
    if w > most_w.max(most_h) || h > most_w.max(most_h) || w.saturating_mul(h) > most_w * most_h {
        bail!("its header declares {w} x {h} pixels: at most {most_w} x {most_h} are read");
    }
    Ok(())
}

/// Reads `path` whole if it is a regular file (symbolic links followed) of at most `cap`
/// bytes; otherwise an error naming `what`, the path and what it is instead.
pub fn read_regular(path: &Path, cap: u64, what: &str) -> Result<Vec<u8>> {
    let meta = std::fs::metadata(path)
        .with_context(|| format!("cannot read {what} '{}'", path.display()))?;
    check_regular(path, &meta, cap, what)?;
    let file = std::fs::File::open(path)
        .with_context(|| format!("cannot read {what} '{}'", path.display()))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(cap + 1)
        .read_to_end(&mut bytes)
        .with_context(|| format!("cannot read {what} '{}'", path.display()))?;
    if bytes.len() as u64 > cap {
        bail!(
            "{what} '{}' grew beyond {} while being read",
            path.display(),
            size(cap)
        );
    }
    Ok(bytes)
}

/// Checks that `meta` describes a regular file of at most `cap` bytes.
pub fn check_regular(path: &Path, meta: &std::fs::Metadata, cap: u64, what: &str) -> Result<()> {
    let ft = meta.file_type();
    if !ft.is_file() {
        let kind = kind_of(&ft);
        bail!("{what} '{}' is {kind}, not a regular file", path.display());
    }
    if meta.len() > cap {
        bail!(
            "{what} '{}' is {}, more than the {} a {what} may have",
            path.display(),
            size(meta.len()),
            size(cap)
        );
    }
    Ok(())
}

/// What a path that is not a regular file is, for messages: "a folder", "a FIFO (named pipe)"...
pub fn kind_of(ft: &std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if ft.is_dir() {
        "a folder"
    } else if ft.is_fifo() {
        "a FIFO (named pipe)"
    } else if ft.is_char_device() {
        "a character device"
    } else if ft.is_block_device() {
        "a block device"
    } else if ft.is_socket() {
        "a socket"
    } else {
        "not a file"
    }
}

fn size(bytes: u64) -> String {
    if bytes >= 1 << 30 {
        format!("{:.1} GiB", bytes as f64 / (1u64 << 30) as f64)
    } else {
        format!("{:.1} MiB", bytes as f64 / (1u64 << 20) as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_folders_and_oversized_files_are_refused() {
        let e = read_regular(Path::new("/dev/zero"), 100, "mesh file").unwrap_err();
        assert!(format!("{e:#}").contains("a character device"), "{e:#}");
        let e = read_regular(Path::new("/tmp"), 100, "mesh file").unwrap_err();
        assert!(format!("{e:#}").contains("a folder"), "{e:#}");
        let dir = std::env::temp_dir().join(format!("translucent-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let big = dir.join("big.obj");
        std::fs::write(&big, vec![b'#'; 200]).unwrap();
        let e = read_regular(&big, 100, "mesh file").unwrap_err();
        assert!(format!("{e:#}").contains("more than the"), "{e:#}");
        assert_eq!(read_regular(&big, 200, "mesh file").unwrap().len(), 200);
        let fifo = dir.join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.map(|s| s.success()).unwrap_or(false) {
            let e = read_regular(&fifo, 100, "scene file").unwrap_err();
            assert!(format!("{e:#}").contains("FIFO"), "{e:#}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
