//! Writing films to image files, and reading images back as films.
//!
//! [`write_film`] picks the format from the file extension:
//!
//! | extension | what is written |
//! | --- | --- |
//! | `.png` | 8-bit sRGB RGB (16-bit with [`OutputOptions::bit_depth16`]), or an indexed PNG (PLTE) with [`OutputOptions::palette`] |
//! | `.exr` | OpenEXR, 32-bit float: `R`, `G`, `B` linear radiance, `Z` depth (`inf` where nothing was hit), `N.X`, `N.Y`, `N.Z` world-space normal |
//! | `.hdr` | Radiance RGBE, linear radiance |
//! | `.ppm` | binary PPM (`P6`), 8-bit sRGB (16-bit big-endian with `bit_depth16`) |
//!
//! PNG and PPM go through exposure and the tone map ([`chiaro_core::film::tonemap`]);
//! EXR and HDR store the film's linear radiance unchanged. NaN never reaches
//! a file: colours are sanitised (NaN, infinite and negative channels become
//! 0), a NaN depth becomes `inf`, a NaN normal zero.
//!
//! Every file is written to a temporary file in the destination directory
//! and renamed into place, so a crash or a full disk never leaves half a file
//! under the final name.
//!
//! [`read_image_as_film`] reads PNG, JPEG, HDR, EXR and PPM back into a
//! linear film (reference images for `compare`).

mod encode;

use crate::error::{IoError, Result};
use crate::images::{MAX_IMAGE_SIDE, decode_image};
use chiaro_core::film::Film;
use chiaro_core::glam::Vec3;
use chiaro_core::scene::ToneMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

pub use chiaro_core::film::palette::PaletteMode;

/// The file extensions [`write_film`] understands (lower case, no dot).
pub const SUPPORTED_EXTENSIONS: &[&str] = &["png", "exr", "hdr", "ppm"];

/// How a film becomes an image file.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputOptions {
    /// Tone map for 8/16-bit outputs (PNG, PPM).
    pub tonemap: ToneMap,
    /// Exposure in stops (`2^exposure` scales radiance) for PNG and PPM.
    pub exposure: f32,
    /// 16 bits per channel for PNG and PPM instead of 8.
    pub bit_depth16: bool,
    /// Write an indexed (palette) PNG instead; only for `.png`.
    pub palette: Option<PaletteMode>,
}

impl Default for OutputOptions {
    fn default() -> Self {
        Self {
            tonemap: ToneMap::default(),
            exposure: 0.0,
            bit_depth16: false,
            palette: None,
        }
    }
}

/// An output file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    /// Portable Network Graphics.
    Png,
    /// OpenEXR.
    Exr,
    /// Radiance RGBE.
    Hdr,
    /// Binary portable pixmap (P6).
    Ppm,
}

impl ImageFormat {
    /// The format for `path`'s extension (case-insensitive).
    ///
    /// # Errors
    /// [`IoError::Format`] naming the file and listing
    /// [`SUPPORTED_EXTENSIONS`] for any other extension or none.
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = crate::lowercase_extension(path);
        match ext.as_str() {
            "png" => Ok(Self::Png),
            "exr" => Ok(Self::Exr),
            "hdr" => Ok(Self::Hdr),
            "ppm" => Ok(Self::Ppm),
            _ => Err(IoError::format(
                path,
                format!(
                    "cannot write {}: the supported output formats are {}",
                    if ext.is_empty() {
                        "a file without an extension".to_string()
                    } else {
                        format!("`.{ext}` files")
                    },
                    SUPPORTED_EXTENSIONS
                        .iter()
                        .map(|e| format!(".{e}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )),
        }
    }
}

/// Checks, before anything is rendered, that a film can be written to
/// `path`: its extension names a known format, it is not a directory, and
/// its directory exists and accepts a new file (probed by creating and
/// removing an empty temporary file there).
///
/// # Errors
/// [`IoError::Format`] for an unknown extension or a directory;
/// [`IoError::Io`] naming `path` when its directory is missing or not
/// writable.
pub fn check_output_path(path: &Path) -> Result<()> {
    ImageFormat::from_path(path)?;
    if path.is_dir() {
        return Err(IoError::format(path, "is a directory, not an image file"));
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !dir.is_dir() {
        return Err(IoError::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("the directory {} does not exist", dir.display()),
            ),
        ));
    }
    let probe = dir.join(format!(
        ".chiaro-write-probe-{}-{}.tmp",
        std::process::id(),
        PROBE_COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::File::create_new(&probe).map_err(|e| IoError::io(path, e))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

static PROBE_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `film` to `path` in the format of its extension (see the module
/// docs), atomically: through a temporary file in the same directory,
/// renamed into place.
///
/// # Errors
/// [`IoError::Format`] for an unknown extension, a palette with a non-PNG
/// file, a film whose buffers do not match its size, or an empty film;
/// [`IoError::Io`] naming `path` if the directory does not exist or the
/// file cannot be written (nothing is left behind).
pub fn write_film(film: &Film, path: &Path, opts: &OutputOptions) -> Result<()> {
    let bytes = encode_film(film, ImageFormat::from_path(path)?, opts)
        .map_err(|message| IoError::format(path, message))?;
    write_atomically(path, &bytes)
}

/// Encodes `film` in `format` in memory: the bytes [`write_film`] writes.
///
/// # Errors
/// A message saying what is wrong (see [`write_film`]).
pub fn encode_film(
    film: &Film,
    format: ImageFormat,
    opts: &OutputOptions,
) -> std::result::Result<Vec<u8>, String> {
    let n = film.width as usize * film.height as usize;
    if film.width == 0 || film.height == 0 {
        return Err("the film is empty (0 pixels)".into());
    }
    if film.color.len() != n || film.depth.len() != n || film.normal.len() != n {
        return Err(format!(
            "the film's buffers do not match its size {}x{}",
            film.width, film.height
        ));
    }
    if opts.palette.is_some() && format != ImageFormat::Png {
        return Err("palette (indexed) output needs a .png file".into());
    }
    match format {
        ImageFormat::Png => match &opts.palette {
            Some(mode) => encode::indexed_png(film, mode, opts),
            None => encode::png(film, opts),
        },
        ImageFormat::Exr => encode::exr(film),
        ImageFormat::Hdr => encode::hdr(film),
        ImageFormat::Ppm => Ok(encode::ppm(film, opts)),
    }
}

/// Writes `bytes` to `path` through a temporary file in the same directory
/// (created exclusively, synced, renamed over `path`); on any failure the
/// temporary file is removed.
///
/// # Errors
/// [`IoError::Io`] naming `path`.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let Some(name) = path.file_name() else {
        return Err(IoError::format(path, "not a file name"));
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let tmp = dir.join(format!(
        ".{}.{}-{}.tmp",
        name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let mut f = std::fs::File::create_new(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        // The temporary may not exist (the directory is missing); either way
        // nothing must be left behind.
        let _ = std::fs::remove_file(&tmp);
        return Err(IoError::io(path, e));
    }
    Ok(())
}

/// Reads an image file (PNG, JPEG, Radiance HDR, OpenEXR, PPM) as a linear
/// film: 8/16-bit files through the sRGB EOTF, HDR and EXR as stored. An
/// EXR's `Z` and `N.X/N.Y/N.Z` channels fill depth and normal; otherwise
/// depth is `inf` and normal zero. Alpha is dropped.
///
/// # Errors
/// [`IoError::Io`] if the file cannot be read; [`IoError::Format`] naming
/// it if it cannot be decoded or is larger than
/// [`MAX_IMAGE_SIDE`] on a side.
pub fn read_image_as_film(path: &Path) -> Result<Film> {
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    let img = if bytes.starts_with(b"P6") {
        encode::decode_ppm(&bytes).map_err(|m| IoError::format(path, m))?
    } else {
        decode_image(&bytes, path, true)?
    };
    if img.width > MAX_IMAGE_SIDE || img.height > MAX_IMAGE_SIDE {
        return Err(IoError::format(path, "image too large"));
    }
    let mut film = Film::new(img.width, img.height);
    for (c, t) in film.color.iter_mut().zip(&img.texels) {
        *c = chiaro_core::shading::sanitize(Vec3::new(t[0], t[1], t[2]));
    }
    if let Some(d) = img.depth {
        film.depth = d;
    }
    if let Some(n) = img.normal {
        film.normal = n;
    }
    Ok(film)
}
