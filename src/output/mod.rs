//! Files the renderer writes: images (PNG, EXR), `timings.json`, `trace.json`.
//! Every file is written to a temporary name in the same folder and renamed into place, so an
//! interrupted run never leaves a partial file under the final name.

mod tonemap;

pub use tonemap::ToneMap;

use crate::graph::timing::{FrameTiming, TimingReport};
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// The suffix of the temporaries this program writes: `.NAME.PID.translucent.tmp`, so that
/// the removal of stale ones never touches a file of anyone else's.
const TEMPORARY_SUFFIX: &str = ".translucent.tmp";

/// Oldest a temporary of a process that is gone must be before it is removed: a process of
/// another host or container writing to the same folder has no entry in this /proc.
const STALE_AFTER: std::time::Duration = std::time::Duration::from_secs(3600);

fn temporary(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}{TEMPORARY_SUFFIX}", std::process::id()))
}

/// The name a file written to `path` is for: the final name where `path` is one of this
/// process's temporaries ([`temporary`]), `path` itself otherwise. Errors name that file,
/// not the temporary the user never sees.
fn destination(path: &Path) -> PathBuf {
    let suffix = format!(".{}{TEMPORARY_SUFFIX}", std::process::id());
    path.file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| n.strip_prefix('.')?.strip_suffix(suffix.as_str()))
        .map_or_else(|| path.to_path_buf(), |n| path.with_file_name(n))
}

/// The context of a failed write of `path`: the file it is for and its folder.
fn cannot_write(path: &Path) -> String {
    let target = destination(path);
    match target.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(dir) => format!(
            "cannot write '{}' (in the output folder '{}')",
            target.display(),
            dir.display()
        ),
        None => format!("cannot write '{}'", target.display()),
    }
}

/// Refuses `path` as a target to replace when something other than a regular file is there: a
/// rename would put a file in place of a device, a FIFO, a socket or a symbolic link (the link
/// replaced, not its target written), and cannot replace a folder.
pub fn check_replaceable(path: &Path) -> Result<()> {
    match std::fs::symlink_metadata(path) {
        Ok(meta) if !meta.file_type().is_file() => {
            let what = if meta.file_type().is_symlink() {
                "a symbolic link"
            } else {
                crate::input::kind_of(&meta.file_type())
            };
            anyhow::bail!(
                "'{}' exists and is {what}: it is not replaced; choose another output name",
                path.display()
            )
        }
        _ => Ok(()),
    }
}

/// Refuses, before any work, a command's output folder `dir` where one of the files it will
/// write (`names`) exists and is not a regular file ([`check_replaceable`]): the refusal
/// comes before minutes of tracing, not after them.
pub fn check_targets(dir: &Path, names: &[&str]) -> Result<()> {
    names
        .iter()
        .try_for_each(|name| check_replaceable(&dir.join(name)))
}

/// A name the viewer's commands write under their output folder: one plain file name, so that
/// what they write stays inside that folder.
pub fn plain_name(name: &str) -> Result<&str> {
    let plain = !name.is_empty()
        && name != "."
        && name != ".."
        && !name.starts_with('.')
        && !name.contains(['/', '\\', '\0'])
        && name.chars().all(|c| !c.is_control());
    if !plain {
        anyhow::bail!(
            "'{name}' is not a plain file name (no folders, no leading dot): the viewer writes only inside its output folder"
        );
    }
    Ok(name)
}

/// Writes a file through a temporary name and a rename. Refuses a target that is not a regular
/// file ([`check_replaceable`]), and removes the temporaries of killed runs in its folder.
pub fn write_atomic(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    check_replaceable(path)?;
    if let Some(dir) = path.parent() {
        remove_stale_temporaries(if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        });
    }
    let tmp = temporary(path);
    let result = write(&tmp).and_then(|_| {
        check_replaceable(path)?;
        std::fs::rename(&tmp, path)
            .with_context(|| format!("cannot move {} into place", path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    // Named once: the encoders below already name the file they write for.
    let context = cannot_write(path);
    result.map_err(|e| {
        if e.to_string() == context {
            e
        } else {
            e.context(context)
        }
    })
}

/// The files of one run, written as a set: each is written under a temporary name, and only
/// when all are written are they renamed into place together. A failed write removes the
/// temporaries and leaves whatever the folder held before, never a new image beside an old
/// scene.toml. Temporaries that a killed run left behind (their process gone) are removed
/// when the next set is opened in the folder.
pub struct OutputSet {
    dir: PathBuf,
    /// The names the set may write (checked against the inputs when it is opened).
    names: &'static [&'static str],
    /// (temporary, final) per file, in order.
    files: Vec<(PathBuf, PathBuf)>,
    committed: bool,
}

impl OutputSet {
    /// Opens a set of `names` in `dir` (created if needed), removing stale temporaries there.
    /// Refuses, before anything is written, a folder where one of `names` would replace one of
    /// `inputs` (the scene file, its mesh or texture): `--out` pointing at the scene's own
    /// folder would otherwise overwrite the user's scene.toml with the resolved one.
    pub fn new(
        dir: &Path,
        names: &'static [&'static str],
        inputs: &[PathBuf],
    ) -> Result<OutputSet> {
        let inputs: Vec<PathBuf> = inputs
            .iter()
            .filter_map(|p| std::fs::canonicalize(p).ok())
            .collect();
        // A folder that is not there yet holds no input.
        if let Ok(canonical) = std::fs::canonicalize(dir) {
            for name in names {
                let target = canonical.join(name);
                let target = std::fs::canonicalize(&target).unwrap_or(target);
                if let Some(input) = inputs.iter().find(|i| **i == target) {
                    anyhow::bail!(
                        "--out {} would overwrite the input '{}' with its {name}: choose another output folder",
                        dir.display(),
                        input.display()
                    );
                }
            }
        }
        create_dir(dir)?;
        remove_stale_temporaries(dir);
        for name in names {
            check_replaceable(&dir.join(name))?;
        }
        // A folder that takes no files (read-only, not ours) is refused now, not after the
        // work: an empty temporary is made and removed again.
        if let Some(first) = names.first() {
            let probe = temporary(&dir.join(first));
            std::fs::write(&probe, b"").with_context(|| cannot_write(&probe))?;
            let _ = std::fs::remove_file(&probe);
        }
        Ok(OutputSet {
            dir: dir.to_path_buf(),
            names,
            files: Vec::new(),
            committed: false,
        })
    }

    /// The path to write `name` (one of the set's names) to: a temporary name in the folder,
    /// renamed into place by [`OutputSet::commit`].
    pub fn path(&mut self, name: &str) -> PathBuf {
        assert!(
            self.names.contains(&name),
            "'{name}' is not among the output set's names {:?}",
            self.names
        );
        let target = self.dir.join(name);
        let tmp = temporary(&target);
        self.files.push((tmp.clone(), target));
        tmp
    }

    /// Writes `NAME.exr` (linear) and `NAME.png` (tone-mapped with `exposure` and `curve`) of
    /// the set.
    pub fn radiance(
        &mut self,
        name: &str,
        width: u32,
        height: u32,
        radiance: &[f32],
        (exposure, curve): (f32, ToneMap),
    ) -> Result<()> {
        encode_exr(&self.path(&format!("{name}.exr")), width, height, radiance)?;
        encode_png(
            &self.path(&format!("{name}.png")),
            width,
            height,
            &tonemap(radiance, exposure, curve),
        )
    }

    /// Writes the set's file `name` with `contents`.
    pub fn text(&mut self, name: &str, contents: &str) -> Result<()> {
        let path = self.path(name);
        std::fs::write(&path, contents).with_context(|| cannot_write(&path))
    }

    /// Moves every file into place, and removes the set's names it did not write (an older
    /// set's). Checks first that no final name is a folder (the one way a rename in the same
    /// folder fails), so that the set lands whole or not at all.
    pub fn commit(mut self) -> Result<()> {
        for (tmp, target) in &self.files {
            if !tmp.is_file() {
                anyhow::bail!("'{}' was not written", target.display());
            }
            check_replaceable(target)?;
        }
        for (tmp, target) in &self.files {
            std::fs::rename(tmp, target)
                .with_context(|| format!("cannot move {} into place", target.display()))?;
        }
        self.committed = true;
        // A name of the set this run did not write belongs to an older set (`truth`'s surface
        // image of a refractive scene beside an index-matched one): it goes.
        for name in self.names {
            let target = self.dir.join(name);
            let written = self.files.iter().any(|(_, t)| *t == target);
            if !written && std::fs::symlink_metadata(&target).is_ok_and(|m| m.is_file()) {
                let _ = std::fs::remove_file(&target);
            }
        }
        Ok(())
    }
}

impl Drop for OutputSet {
    fn drop(&mut self) {
        if !self.committed {
            for (tmp, _) in &self.files {
                let _ = std::fs::remove_file(tmp);
            }
        }
    }
}

/// Removes this program's temporaries (`.NAME.PID.translucent.tmp`) in `dir` whose process is
/// gone and that are older than `STALE_AFTER` (an hour); once per folder and process (a run that
/// writes many files scans its folder once).
pub fn remove_stale_temporaries(dir: &Path) {
    static CLEANED: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
    let key = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    if let Ok(mut cleaned) = CLEANED.lock() {
        if cleaned.contains(&key) {
            return;
        }
        cleaned.push(key);
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(stem) = name
            .strip_prefix('.')
            .and_then(|n| n.strip_suffix(TEMPORARY_SUFFIX))
        else {
            continue;
        };
        let Some(pid) = stem.rsplit('.').next().and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        let old = e
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age >= STALE_AFTER);
        let regular = e.file_type().is_ok_and(|t| t.is_file());
        if regular
            && old
            && pid != std::process::id()
            && !Path::new(&format!("/proc/{pid}")).exists()
        {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// Writes tightly packed RGBA8 pixels as PNG ([`write_atomic`]).
pub fn write_png(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<()> {
    write_atomic(path, |tmp| encode_png(tmp, width, height, rgba))
}

/// Writes PNG to `path` directly: for an [`OutputSet`]'s temporary paths.
pub fn encode_png(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<()> {
    image::save_buffer_with_format(
        path,
        rgba,
        width,
        height,
        image::ColorType::Rgba8,
        image::ImageFormat::Png,
    )
    .map_err(|e| match e {
        // The I/O error alone: the codec's wrapper would print it twice.
        image::ImageError::IoError(io) => anyhow::Error::new(io),
        other => anyhow::Error::new(other),
    })
    .with_context(|| cannot_write(path))
}

/// Writes linear RGBA f32 pixels (row-major, top row first) as an OpenEXR file
/// ([`write_atomic`]).
pub fn write_exr(path: &Path, width: u32, height: u32, rgba: &[f32]) -> Result<()> {
    write_atomic(path, |tmp| encode_exr(tmp, width, height, rgba))
}

/// Writes OpenEXR to `path` directly: for an [`OutputSet`]'s temporary paths. The blocks are
/// compressed and written in order on one thread: the parallel writer stores them in the
/// order its threads finish, so the same image would give different files.
pub fn encode_exr(path: &Path, width: u32, height: u32, rgba: &[f32]) -> Result<()> {
    use exr::prelude::*;
    let w = width as usize;
    let channels = SpecificChannels::rgba(|Vec2(x, y)| {
        let i = 4 * (y * w + x);
        (rgba[i], rgba[i + 1], rgba[i + 2], rgba[i + 3])
    });
    Image::from_channels((w, height as usize), channels)
        .write()
        .non_parallel()
        .to_file(path)
        .map_err(exr_error)
        .with_context(|| cannot_write(path))
}

/// An OpenEXR error, its I/O error alone where it is one: the codec's wrapper would print it
/// twice.
pub(crate) fn exr_error(e: exr::error::Error) -> anyhow::Error {
    match e {
        exr::error::Error::Io(io) => anyhow::Error::new(io),
        other => anyhow::Error::new(other),
    }
}

/// Reads an RGBA EXR written by [`write_exr`] (for tests and comparisons).
pub fn read_exr(path: &Path) -> Result<(u32, u32, Vec<f32>)> {
    use exr::prelude::*;
    let meta =
        std::fs::metadata(path).with_context(|| format!("cannot read '{}'", path.display()))?;
    crate::input::check_regular(path, &meta, crate::input::MAX_DATA_BYTES, "image")?;
    // The declared size, checked before the decoder allocates what the header claims.
    let header = exr::meta::MetaData::read_from_file(path, false)
        .with_context(|| format!("cannot read '{}'", path.display()))?;
    let most = crate::input::MAX_IMAGE_SIDE as u64;
    for layer in &header.headers {
        let (w, h) = (layer.layer_size.width(), layer.layer_size.height());
        crate::input::check_declared_size(w as u64, h as u64, most, most)
            .with_context(|| format!("'{}'", path.display()))?;
    }
    let image = read_first_rgba_layer_from_file(
        path,
        |resolution, _| {
            (
                resolution.width(),
                vec![0f32; resolution.width() * resolution.height() * 4],
            )
        },
        |(w, px), pos, (r, g, b, a): (f32, f32, f32, f32)| {
            let i = 4 * (pos.y() * *w + pos.x());
            px[i..i + 4].copy_from_slice(&[r, g, b, a]);
        },
    )
    .with_context(|| format!("cannot read '{}'", path.display()))?;
    let size = image.layer_data.size;
    Ok((
        size.width() as u32,
        size.height() as u32,
        image.layer_data.channel_data.pixels.1,
    ))
}

/// Creates the output folder `dir` (and its parents), naming it in the error.
/// Where that fails because the path or a folder above it is a file, the file is named
/// (the system's own word is "File exists").
pub fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| {
        let message = format!("cannot create output folder '{}'", dir.display());
        match dir
            .ancestors()
            .find(|a| !a.as_os_str().is_empty() && a.exists() && !a.is_dir())
        {
            Some(file) => {
                anyhow::anyhow!("{message}: '{}' is a file, not a folder", file.display())
            }
            None => anyhow::Error::new(e).context(message),
        }
    })
}

/// RGBA8 premultiplied by alpha (the mean of a pixel's samples, transparent black off the
/// object) to straight alpha: each colour over the covered share.
pub fn unpremultiply(mut rgba: Vec<u8>) -> Vec<u8> {
    for p in rgba.chunks_exact_mut(4) {
        let a = p[3] as u32;
        if a > 0 && a < 255 {
            for c in &mut p[..3] {
                *c = ((*c as u32 * 255 + a / 2) / a).min(255) as u8;
            }
        }
    }
    rgba
}

/// Linear radiance (premultiplied by alpha) to sRGB RGBA8 with straight alpha: times
/// `exposure`, through `curve`, sRGB-encoded, as `glsl/composite.frag` does for a fully
/// covered pixel.
pub fn tonemap(radiance: &[f32], exposure: f32, curve: ToneMap) -> Vec<u8> {
    let encode = |c: f32| {
        let s = if c <= 0.0031308 {
            12.92 * c
        } else {
            1.055 * c.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0 + 0.5) as u8
    };
    radiance
        .chunks(4)
        .flat_map(|p| {
            let a = p[3].clamp(0.0, 1.0);
            let straight = exposure / if a > 0.0 { a } else { 1.0 };
            let c = curve.apply([p[0] * straight, p[1] * straight, p[2] * straight]);
            [
                encode(c[0]),
                encode(c[1]),
                encode(c[2]),
                (a * 255.0 + 0.5) as u8,
            ]
        })
        .collect()
}

/// Writes `timings.json` ([`write_atomic`]).
pub fn write_timings(path: &Path, report: &TimingReport) -> Result<()> {
    write_atomic(path, |tmp| encode_timings(tmp, report))
}

/// Writes `timings.json` to `path` directly: for an [`OutputSet`]'s temporary paths.
pub fn encode_timings(path: &Path, report: &TimingReport) -> Result<()> {
    std::fs::write(path, serde_json::to_string_pretty(report)?).with_context(|| cannot_write(path))
}

/// Writes `trace.json` ([`write_atomic`], [`encode_trace`]).
pub fn write_trace(path: &Path, pass_names: &[String], frames: &[FrameTiming]) -> Result<()> {
    write_atomic(path, |tmp| encode_trace(tmp, pass_names, frames))
}

/// Writes `trace.json` to `path` directly, in Chrome trace-event format: one track for the GPU
/// passes, one for the host's frame wall time. Frames are laid end to end on the host clock.
pub fn encode_trace(path: &Path, pass_names: &[String], frames: &[FrameTiming]) -> Result<()> {
    let mut events = Vec::new();
    events.push(serde_json::json!({"name": "thread_name", "ph": "M", "pid": 1, "tid": 1, "args": {"name": "GPU passes"}}));
    events.push(serde_json::json!({"name": "thread_name", "ph": "M", "pid": 1, "tid": 2, "args": {"name": "host frame (wall)"}}));
    let mut t0_us = 0.0;
    for (f, frame) in frames.iter().enumerate() {
        events.push(serde_json::json!({
            "name": format!("frame {f}"), "cat": "frame", "ph": "X", "pid": 1, "tid": 2,
            "ts": t0_us, "dur": frame.wall_ms * 1e3,
        }));
        for (i, name) in pass_names
            .iter()
            .enumerate()
            .filter(|(i, _)| !frame.pass_ms[*i].is_nan())
        {
            events.push(serde_json::json!({
                "name": name, "cat": "pass", "ph": "X", "pid": 1, "tid": 1,
                "ts": t0_us + frame.pass_start_ms[i] * 1e3, "dur": frame.pass_ms[i] * 1e3,
                "args": {"frame": f},
            }));
        }
        t0_us += frame.wall_ms * 1e3;
    }
    let trace = serde_json::json!({"traceEvents": events, "displayTimeUnit": "ms"});
    std::fs::write(path, serde_json::to_string(&trace)?).with_context(|| cannot_write(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An output folder that is a file, or lies under one, is named as a file.
    #[test]
    fn an_output_folder_that_is_a_file_is_named() {
        let file =
            std::env::temp_dir().join(format!("translucent-out-file-{}", std::process::id()));
        std::fs::write(&file, b"").unwrap();
        for dir in [file.clone(), file.join("below")] {
            let e = format!("{:#}", create_dir(&dir).unwrap_err());
            let want = format!("'{}' is a file, not a folder", file.display());
            assert!(e.contains(&want), "{e}");
        }
        std::fs::remove_file(&file).unwrap();
    }

    /// A failed write names the file it was for (not the temporary) and its folder once, and
    /// the I/O error once, whichever encoder or path failed.
    #[test]
    fn a_failed_write_names_its_file_once() {
        let dir = std::env::temp_dir()
            .join(format!("translucent-out-missing-{}", std::process::id()))
            .join("gone");
        let px = [0.5f32; 4];
        let message = |r: Result<()>| format!("{:#}", r.unwrap_err());
        for (name, result) in [
            ("a.exr", message(write_exr(&dir.join("a.exr"), 1, 1, &px))),
            (
                "a.png",
                message(write_png(&dir.join("a.png"), 1, 1, &[0u8; 4])),
            ),
            (
                "t.json",
                message(write_atomic(&dir.join("t.json"), |p| {
                    Ok(std::fs::write(p, b"{}")?)
                })),
            ),
        ] {
            let expected = format!(
                "cannot write '{}' (in the output folder '{}'): ",
                dir.join(name).display(),
                dir.display()
            );
            assert!(result.starts_with(&expected), "{result}");
            let rest = &result[expected.len()..];
            assert_eq!(rest.matches("os error 2").count(), 1, "{result}");
            assert!(!result.contains(TEMPORARY_SUFFIX), "{result}");
        }
    }

    #[test]
    fn exr_round_trip_and_no_temporaries_left() {
        let dir = std::env::temp_dir().join(format!("translucent-out-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let px: Vec<f32> = (0..2 * 3 * 4).map(|i| i as f32 * 0.25).collect();
        let path = dir.join("x.exr");
        write_exr(&path, 2, 3, &px).unwrap();
        let (w, h, back) = read_exr(&path).unwrap();
        assert_eq!((w, h), (2, 3));
        assert_eq!(back, px);
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        // A failed write leaves nothing behind under the final name.
        let bad = dir.join("missing-dir").join("y.png");
        assert!(write_png(&bad, 1, 1, &[0, 0, 0, 255]).is_err());
        assert!(!bad.exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The same image gives the same file, byte for byte: an image of many compressed blocks,
    /// each compressing to a different size, written several times.
    #[test]
    fn the_same_image_gives_the_same_exr_file() {
        let dir = std::env::temp_dir().join(format!("translucent-same-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (w, h) = (512u32, 512u32);
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let px: Vec<f32> = (0..w * h * 4)
            .map(|i| {
                // Noise in the first rows, black below: the first blocks take far longer to
                // compress than the last, as a render's object rows do against its background.
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                if i / (4 * w) < h / 4 {
                    (state >> 40) as f32 * 1e-3
                } else {
                    0.0
                }
            })
            .collect();
        let first = dir.join("0.exr");
        write_exr(&first, w, h, &px).unwrap();
        let bytes = std::fs::read(&first).unwrap();
        for k in 1..6 {
            let path = dir.join(format!("{k}.exr"));
            write_exr(&path, w, h, &px).unwrap();
            assert!(std::fs::read(&path).unwrap() == bytes, "write {k} differs");
        }
        assert_eq!(read_exr(&first).unwrap().2, px);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn only_regular_files_are_replaced_and_stale_temporaries_go() {
        let dir = std::env::temp_dir().join(format!("translucent-replace-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let target = dir.join("target.txt");
        std::fs::write(&target, b"kept").unwrap();
        let link = dir.join("link.txt");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let folder = dir.join("folder");
        std::fs::create_dir(&folder).unwrap();
        for (path, needle) in [(&link, "a symbolic link"), (&folder, "a folder")] {
            let e = write_png(path, 1, 1, &[0, 0, 0, 255]).unwrap_err();
            assert!(format!("{e:#}").contains(needle), "{e:#}");
        }
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&target).unwrap(), b"kept");
        // A regular file is replaced; a temporary of this program left an hour ago by a
        // process that is gone (no pid is above 2^22 on Linux) is removed by the next write in
        // its folder; a fresh one, and a file of the same shape not ours, stay.
        let stale = dir.join(".cache.bin.4294967.translucent.tmp");
        let fresh = dir.join(".other.bin.4294967.translucent.tmp");
        let foreign = dir.join(".notes.2023.tmp");
        for f in [&stale, &fresh, &foreign] {
            std::fs::write(f, b"left by a killed run").unwrap();
        }
        let hour_ago = std::time::SystemTime::now() - STALE_AFTER;
        std::fs::File::options()
            .write(true)
            .open(&stale)
            .unwrap()
            .set_modified(hour_ago)
            .unwrap();
        write_atomic(&target, |p| Ok(std::fs::write(p, b"new")?)).unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        assert!(!stale.exists());
        assert!(fresh.exists() && foreign.exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A folder the set cannot write into is refused when the set is opened, before any work,
    /// and the refusal names the file the set would have written first. (Where nothing can be
    /// written at the probe's name: a folder in its place, as a read-only folder refuses every
    /// name.)
    #[test]
    fn a_set_is_refused_where_nothing_can_be_written() {
        let dir = std::env::temp_dir().join(format!("translucent-probe-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        const NAMES: &[&str] = &["a.txt"];
        let blocked = temporary(&dir.join("a.txt"));
        std::fs::create_dir_all(&blocked).unwrap();
        let refused = OutputSet::new(&dir, NAMES, &[]).err().expect("refused");
        let message = format!("{refused:#}");
        assert!(
            message.starts_with(&format!("cannot write '{}'", dir.join("a.txt").display())),
            "{message}"
        );
        std::fs::remove_dir(&blocked).unwrap();
        assert!(OutputSet::new(&dir, NAMES, &[]).is_ok());
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert!(left.is_empty(), "the probe stayed: {left:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A set lands whole: an uncommitted one leaves nothing, a committed one its files and
    /// none of an older set's that it did not write.
    #[test]
    fn a_set_lands_whole_and_replaces_an_older_set() {
        let dir = std::env::temp_dir().join(format!("translucent-set-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        const NAMES: &[&str] = &["a.txt", "b.txt", "c.txt"];
        for name in NAMES {
            std::fs::write(dir.join(name), b"old").unwrap();
        }
        {
            let mut set = OutputSet::new(&dir, NAMES, &[]).unwrap();
            set.text("a.txt", "new").unwrap();
            // Dropped without a commit: a failure part way.
        }
        for name in NAMES {
            assert_eq!(std::fs::read(dir.join(name)).unwrap(), b"old");
        }
        let mut set = OutputSet::new(&dir, NAMES, &[]).unwrap();
        set.text("a.txt", "new").unwrap();
        set.text("b.txt", "new").unwrap();
        set.commit().unwrap();
        assert_eq!(std::fs::read(dir.join("a.txt")).unwrap(), b"new");
        assert_eq!(std::fs::read(dir.join("b.txt")).unwrap(), b"new");
        assert!(!dir.join("c.txt").exists(), "an older set's file stayed");
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert_eq!(left.len(), 2, "temporaries left");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn plain_names_stay_in_their_folder() {
        for ok in ["shot", "scene-001", "a b", "x.y"] {
            assert_eq!(plain_name(ok).unwrap(), ok);
        }
        for bad in [
            "", ".", "..", "../x", "/abs", "a/b", ".hidden", "a\\b", "a\nb",
        ] {
            assert!(plain_name(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn trace_has_one_event_per_pass_and_frame() {
        let dir = std::env::temp_dir().join(format!("translucent-trace-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let frames = vec![
            FrameTiming {
                pass_ms: vec![1.0, 2.0],
                pass_start_ms: vec![0.0, 1.0],
                gpu_ms: 3.0,
                wall_ms: 4.0
            };
            3
        ];
        let names = vec!["a".to_string(), "b".to_string()];
        let path = dir.join("trace.json");
        write_trace(&path, &names, &frames).unwrap();
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let events = v["traceEvents"].as_array().unwrap();
        let passes = events.iter().filter(|e| e["cat"] == "pass").count();
        assert_eq!(passes, 6);
        let last_b = events.iter().rfind(|e| e["name"] == "b").unwrap();
        assert_eq!(last_b["ts"].as_f64().unwrap(), 8000.0 + 1000.0);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
