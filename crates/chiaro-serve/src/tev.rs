//! A client of the [tev](https://github.com/Tom94/tev) image viewer's TCP
//! protocol, for `chiaro render ... --display-server HOST:PORT` (pbrt-v4's
//! `--display-server`): the image is created in tev, then its pixels are
//! sent in bands as they are rendered.
//!
//! # Wire format
//! Every packet is little-endian: a `u32` total length (including itself),
//! an `i8` packet type, then type-specific fields; strings are UTF-8 and
//! NUL-terminated. The layouts below are those of tev's `Ipc.h`, as written
//! by tev's own Python client (`tevclient.packet` on PyPI, v1.0.4), against
//! which `tests/tev_protocol.rs` checks these encoders byte for byte:
//!
//! * create image (type 4): `grab_focus: i8`, `name`, `width: i32`,
//!   `height: i32`, `n_channels: i32`, `n_channels` channel names;
//! * update image (type 6): `grab_focus: i8`, `name`, `n_channels: i32`,
//!   channel names, `x, y, width, height: i32`, `n_channels` offsets `i64`,
//!   `n_channels` strides `i64`, then `width * height * n_channels` `f32`
//!   pixel values, row-major with the channels interleaved (offset `c`,
//!   stride `n_channels`);
//! * close image (type 2): `name`.

use chiaro::{Film, Progress, RenderSettings, Scene, Technique};
use std::io::Write;
use std::net::{TcpStream, ToSocketAddrs};
use std::time::Duration;
use thiserror::Error;

/// tev's default IPC port.
pub const DEFAULT_PORT: u16 = 14158;

/// Largest pixel payload of one update packet (bytes); larger regions are
/// split into several packets of whole rows.
pub const MAX_UPDATE_BYTES: usize = 1 << 22;

const TYPE_CLOSE_IMAGE: i8 = 2;
const TYPE_CREATE_IMAGE: i8 = 4;
const TYPE_UPDATE_IMAGE: i8 = 6;

/// What can go wrong talking to tev.
#[derive(Debug, Error)]
pub enum TevError {
    /// The address did not resolve or nothing accepted the connection.
    #[error("cannot connect to the tev display server at {addr}: {source}")]
    Connect {
        /// The address as given.
        addr: String,
        /// The underlying error.
        source: std::io::Error,
    },
    /// Sending a packet failed (tev was closed, the network went away).
    #[error("lost the connection to the tev display server: {0}")]
    Send(#[from] std::io::Error),
    /// A packet's arguments cannot be encoded.
    #[error("cannot encode a tev packet: {0}")]
    Encode(String),
    /// The render itself failed.
    #[error(transparent)]
    Render(#[from] chiaro::Error),
}

/// Appends a NUL-terminated string; names with a NUL cannot be encoded.
fn put_str(out: &mut Vec<u8>, s: &str) -> Result<(), TevError> {
    if s.as_bytes().contains(&0) {
        return Err(TevError::Encode(format!("`{s}` contains a NUL byte")));
    }
    out.extend_from_slice(s.as_bytes());
    out.push(0);
    Ok(())
}

fn put_i32(out: &mut Vec<u8>, v: u32) -> Result<(), TevError> {
    let v = i32::try_from(v).map_err(|_| TevError::Encode(format!("{v} is too large")))?;
    out.extend_from_slice(&v.to_le_bytes());
    Ok(())
}

/// Writes the total length into the first four bytes.
fn finish(mut out: Vec<u8>) -> Result<Vec<u8>, TevError> {
    let len = u32::try_from(out.len())
        .map_err(|_| TevError::Encode("packet larger than 4 GiB".into()))?;
    out[0..4].copy_from_slice(&len.to_le_bytes());
    Ok(out)
}

fn header(kind: i8) -> Vec<u8> {
    let mut out = vec![0u8; 4];
    out.push(kind as u8);
    out
}

/// The bytes of a "create image" packet: a black `width` x `height` image
/// called `name` with the given channels (`["R", "G", "B"]` for a render).
///
/// # Errors
/// [`TevError::Encode`] for a NUL in a name or a size beyond `i32`.
pub fn create_image_packet(
    name: &str,
    width: u32,
    height: u32,
    channels: &[&str],
    grab_focus: bool,
) -> Result<Vec<u8>, TevError> {
    let mut out = header(TYPE_CREATE_IMAGE);
    out.push(u8::from(grab_focus));
    put_str(&mut out, name)?;
    put_i32(&mut out, width)?;
    put_i32(&mut out, height)?;
    put_i32(&mut out, channels.len() as u32)?;
    for c in channels {
        put_str(&mut out, c)?;
    }
    finish(out)
}

/// The bytes of an "update image" packet setting the `width` x `height`
/// region at (`x`, `y`) of image `name`. `data` holds the region's values
/// row-major with the channels interleaved (`data[(row * width + col) *
/// channels.len() + c]`).
///
/// # Errors
/// [`TevError::Encode`] if `data` has the wrong length, a name has a NUL,
/// or a number exceeds `i32`.
pub fn update_image_packet(
    name: &str,
    channels: &[&str],
    x: u32,
    y: u32,
    width: u32,
    height: u32,
    data: &[f32],
    grab_focus: bool,
) -> Result<Vec<u8>, TevError> {
    let n = channels.len();
    if data.len() != width as usize * height as usize * n {
        return Err(TevError::Encode(format!(
            "{} values for a {width}x{height} region of {n} channels",
            data.len()
        )));
    }
    let mut out = header(TYPE_UPDATE_IMAGE);
    out.reserve(data.len() * 4 + 64);
    out.push(u8::from(grab_focus));
    put_str(&mut out, name)?;
    put_i32(&mut out, n as u32)?;
    for c in channels {
        put_str(&mut out, c)?;
    }
    for v in [x, y, width, height] {
        put_i32(&mut out, v)?;
    }
    for c in 0..n {
        out.extend_from_slice(&(c as i64).to_le_bytes());
    }
    for _ in 0..n {
        out.extend_from_slice(&(n as i64).to_le_bytes());
    }
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    finish(out)
}

/// The bytes of a "close image" packet.
///
/// # Errors
/// [`TevError::Encode`] for a NUL in the name.
pub fn close_image_packet(name: &str) -> Result<Vec<u8>, TevError> {
    let mut out = header(TYPE_CLOSE_IMAGE);
    put_str(&mut out, name)?;
    finish(out)
}

/// A connection to a running tev.
#[derive(Debug)]
pub struct TevClient {
    stream: TcpStream,
}

impl TevClient {
    /// Connects to tev at `addr` (`HOST:PORT`, or `HOST` for port
    /// [`DEFAULT_PORT`]), waiting at most 5 seconds.
    ///
    /// # Errors
    /// [`TevError::Connect`] if the address does not resolve or refuses.
    pub fn connect(addr: &str) -> Result<Self, TevError> {
        let with_port = if addr
            .rsplit_once(':')
            .is_some_and(|(_, p)| p.parse::<u16>().is_ok())
        {
            addr.to_string()
        } else {
            format!("{addr}:{DEFAULT_PORT}")
        };
        let err = |source| TevError::Connect {
            addr: addr.into(),
            source,
        };
        let mut last = std::io::Error::new(std::io::ErrorKind::NotFound, "no address");
        for a in with_port.to_socket_addrs().map_err(err)? {
            match TcpStream::connect_timeout(&a, Duration::from_secs(5)) {
                Ok(stream) => {
                    // Nagle would delay the last band; tev reads whole packets anyway.
                    let _ = stream.set_nodelay(true);
                    return Ok(Self { stream });
                }
                Err(e) => last = e,
            }
        }
        Err(err(last))
    }

    /// Creates (or replaces) image `name` in tev.
    ///
    /// # Errors
    /// [`TevError::Encode`] or [`TevError::Send`].
    pub fn create_image(
        &mut self,
        name: &str,
        width: u32,
        height: u32,
        channels: &[&str],
    ) -> Result<(), TevError> {
        let p = create_image_packet(name, width, height, channels, true)?;
        self.stream.write_all(&p)?;
        Ok(())
    }

    /// Sets a region of image `name` (see [`update_image_packet`] for the
    /// layout of `data`), split into packets of at most
    /// [`MAX_UPDATE_BYTES`] of pixels.
    ///
    /// # Errors
    /// [`TevError::Encode`] or [`TevError::Send`].
    pub fn update_image(
        &mut self,
        name: &str,
        x: u32,
        y: u32,
        width: u32,
        height: u32,
        channels: &[&str],
        data: &[f32],
    ) -> Result<(), TevError> {
        let row = width as usize * channels.len();
        if data.len() != row * height as usize {
            return Err(TevError::Encode(format!(
                "{} values for a {width}x{height} region of {} channels",
                data.len(),
                channels.len()
            )));
        }
        let rows_per_packet = (MAX_UPDATE_BYTES / (row * 4).max(1)).max(1);
        let mut r0 = 0usize;
        while r0 < height as usize {
            let r1 = (r0 + rows_per_packet).min(height as usize);
            let p = update_image_packet(
                name,
                channels,
                x,
                y + r0 as u32,
                width,
                (r1 - r0) as u32,
                &data[r0 * row..r1 * row],
                false,
            )?;
            self.stream.write_all(&p)?;
            r0 = r1;
        }
        Ok(())
    }

    /// Sends rows `y0..y1` of `film`'s colour as `R`, `G`, `B` (linear
    /// radiance; tev does its own display transform) to image `name`.
    ///
    /// # Errors
    /// [`TevError::Encode`] or [`TevError::Send`].
    pub fn send_rows(&mut self, name: &str, film: &Film, y0: u32, y1: u32) -> Result<(), TevError> {
        let y1 = y1.min(film.height);
        if y0 >= y1 {
            return Ok(());
        }
        let start = film.index(0, y0);
        let end = film.index(0, y1 - 1) + film.width as usize;
        let data: Vec<f32> = film.color[start..end]
            .iter()
            .flat_map(|c| {
                let c = chiaro_core::shading::sanitize(*c);
                [c.x, c.y, c.z]
            })
            .collect();
        self.update_image(name, 0, y0, film.width, y1 - y0, &RGB, &data)
    }

    /// Closes image `name` in tev.
    ///
    /// # Errors
    /// [`TevError::Encode`] or [`TevError::Send`].
    pub fn close_image(&mut self, name: &str) -> Result<(), TevError> {
        let p = close_image_packet(name)?;
        self.stream.write_all(&p)?;
        Ok(())
    }
}

/// The channel names of a colour render.
pub const RGB: [&str; 3] = ["R", "G", "B"];

/// Whether `technique` honours [`RenderSettings::crop`] (so that rendering
/// in bands costs no more than a whole render). The others are rendered
/// whole and sent at the end.
pub fn supports_crop(technique: Technique) -> bool {
    matches!(technique, Technique::Preview | Technique::Path)
}

/// Scenes with more triangles than this are rendered whole, not in bands:
/// every band is a separate render that prepares the scene (and builds its
/// BVH) again, which for a ~1M-triangle scene costs about a second a band
/// (BENCHMARKS.md, "Web viewer").
pub const BAND_TRIANGLE_LIMIT: usize = 100_000;

/// Rows per band when rendering progressively: about 8 bands, at least 8
/// rows each.
pub fn band_height(height: u32) -> u32 {
    height.div_ceil(8).max(8)
}

/// Renders `scene` with `settings` by `render` (a whole render, given the
/// settings of each band) in horizontal bands (through
/// [`RenderSettings::crop`], where the technique supports it), calling
/// `on_band(film, y0, y1)` after each band with the film so far; returns the
/// whole film (identical to a plain render) and the summed statistics.
/// A technique without crop support, or a scene of more than
/// [`BAND_TRIANGLE_LIMIT`] triangles, is rendered whole and reported as one
/// band.
///
/// # Errors
/// The render's error, or the first error `on_band` returns.
pub(crate) fn render_in_bands<E: From<chiaro::Error>>(
    scene: &Scene,
    settings: &RenderSettings,
    mut render: impl FnMut(&RenderSettings) -> chiaro::Result<(Film, chiaro::RenderStats)>,
    mut on_band: impl FnMut(&Film, u32, u32) -> Result<(), E>,
) -> Result<(Film, chiaro::RenderStats), E> {
    if !supports_crop(settings.technique)
        || settings.crop.is_some()
        || scene.triangle_count() > BAND_TRIANGLE_LIMIT
    {
        let (film, stats) = render(settings)?;
        on_band(&film, 0, film.height)?;
        return Ok((film, stats));
    }
    let mut full = Film::new(settings.width, settings.height);
    let mut total = chiaro::RenderStats::default();
    let step = band_height(settings.height);
    let mut y0 = 0;
    while y0 < settings.height {
        let y1 = (y0 + step).min(settings.height);
        let mut band = settings.clone();
        band.crop = Some([0, y0, settings.width, y1]);
        let (film, stats) = render(&band)?;
        copy_rows(&film, &mut full, y0, y1);
        total.elapsed += stats.elapsed;
        total.rays += stats.rays;
        total.camera_rays += stats.camera_rays;
        total.triangles = stats.triangles;
        on_band(&full, y0, y1)?;
        y0 = y1;
    }
    Ok((full, total))
}

/// Copies rows `y0..y1` (colour, depth, normal) from `src` to `dst`, which
/// have the same size.
pub(crate) fn copy_rows(src: &Film, dst: &mut Film, y0: u32, y1: u32) {
    if src.width != dst.width || src.height != dst.height || y0 >= y1 {
        return;
    }
    let a = src.index(0, y0);
    let b = src.index(0, y1 - 1) + src.width as usize;
    dst.color[a..b].copy_from_slice(&src.color[a..b]);
    dst.depth[a..b].copy_from_slice(&src.depth[a..b]);
    dst.normal[a..b].copy_from_slice(&src.normal[a..b]);
}

/// `chiaro render ... --display-server ADDR`: connects to tev at `addr`,
/// creates image `name` of the render's size, renders (in bands where the
/// technique supports crop) and sends each band as it completes. Returns the
/// film and statistics of the render, as [`chiaro::render_with_stats`] does.
///
/// # Errors
/// [`TevError::Connect`] before rendering if tev is not there; a lost
/// connection during the render stops it with [`TevError::Send`].
pub fn render_to_tev(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
    addr: &str,
    name: &str,
) -> Result<(Film, chiaro::RenderStats), TevError> {
    let mut client = TevClient::connect(addr)?;
    client.create_image(name, settings.width, settings.height, &RGB)?;
    render_in_bands(
        scene,
        settings,
        |s| chiaro::render_with_stats(scene, s, progress),
        |film, y0, y1| client.send_rows(name, film, y0, y1),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn update_rejects_wrong_data_length() {
        assert!(update_image_packet("a", &RGB, 0, 0, 2, 2, &[0.0; 11], false).is_err());
        assert!(update_image_packet("a", &RGB, 0, 0, 2, 2, &[0.0; 12], false).is_ok());
    }

    #[test]
    fn names_with_nul_are_refused() {
        assert!(create_image_packet("a\0b", 1, 1, &RGB, true).is_err());
        assert!(close_image_packet("x\0").is_err());
    }

    #[test]
    fn length_prefix_is_total_length() {
        let p = close_image_packet("abc").expect("encodes");
        assert_eq!(p.len(), 4 + 1 + 4);
        assert_eq!(
            u32::from_le_bytes([p[0], p[1], p[2], p[3]]) as usize,
            p.len()
        );
        assert_eq!(p[4], 2);
    }

    #[test]
    fn band_height_covers_image() {
        for h in [1, 7, 8, 64, 255, 1080] {
            let b = band_height(h);
            assert!(b >= 1 && b * 8 >= h.min(64), "{h} {b}");
        }
    }
}
