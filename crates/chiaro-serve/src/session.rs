//! One WebSocket connection: a reader loop that also writes the frames a
//! render worker produces, and the worker that renders the latest request
//! (cancelling the one before it).

use crate::State;
use crate::protocol::{FrameHeader, Job, Request, encode_frame, make_job};
use crate::tev::render_in_bands;
use chiaro::io::output::{ImageFormat, OutputOptions, encode_film};
use chiaro::{Film, Progress, Technique};
use chiaro_core::film::metrics;
use serde_json::json;
use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tungstenite::protocol::{Role, WebSocketConfig};
use tungstenite::{Message, WebSocket};

/// The JSON of `/api/info`: the scene, the choices and the limits.
pub(crate) fn info_json(state: &State) -> String {
    let r = &state.scene.render;
    json!({
        "scene": state.scene_name,
        "width": r.width,
        "height": r.height,
        "samples": r.samples,
        "technique": r.technique.name(),
        "techniques": chiaro::available_techniques().iter().map(|t| t.name()).collect::<Vec<_>>(),
        "shadows": ["scene", "none", "map", "volume", "ray", "object", "scanline"],
        "transparency": ["scene", "interpolated", "screen-door", "filtered"],
        "models": ["scene", "phong", "blinn", "torrance-sparrow"],
        "limits": state.limits,
        "triangles": state.scene.triangle_count(),
    })
    .to_string()
}

/// A render's progress: cancelled when a newer request arrives or the
/// connection closes.
struct JobProgress(Arc<AtomicBool>);

impl Progress for JobProgress {
    fn begin(&self, _stage: &str, _total: u64) {}
    fn advance(&self, _n: u64) {}
    fn cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

enum Command {
    Render(Job, Arc<AtomicBool>),
    Save { view: usize, format: String },
}

/// Serves one upgraded connection until it closes.
pub(crate) fn run(stream: TcpStream, state: Arc<State>) {
    // Short read timeouts let this one thread both read requests and write
    // the worker's frames.
    let _ = stream.set_read_timeout(Some(Duration::from_millis(20)));
    let _ = stream.set_nodelay(true);
    let config = WebSocketConfig::default()
        .max_message_size(Some(state.limits.max_message_bytes))
        .max_frame_size(Some(state.limits.max_message_bytes));
    let mut ws = WebSocket::from_raw_socket(stream, Role::Server, Some(config));
    let (cmd_tx, cmd_rx) = channel::<Command>();
    let (out_tx, out_rx) = channel::<Message>();
    let current: Arc<Mutex<Option<Arc<AtomicBool>>>> = Arc::new(Mutex::new(None));
    let worker_state = Arc::clone(&state);
    let worker = std::thread::Builder::new()
        .name("chiaro-serve-render".into())
        .spawn(move || worker(&worker_state, &cmd_rx, &out_tx));
    if worker.is_err() {
        return;
    }
    let cancel_current = |current: &Mutex<Option<Arc<AtomicBool>>>| {
        if let Ok(mut c) = current.lock()
            && let Some(flag) = c.take()
        {
            flag.store(true, Ordering::Relaxed);
        }
    };
    'conn: loop {
        match ws.read() {
            Ok(Message::Text(text)) => match Request::parse(text.as_str()) {
                Ok(Request::Render {
                    id,
                    width,
                    height,
                    orbit,
                    progressive,
                    views,
                }) => match make_job(
                    &state.scene,
                    &state.limits,
                    id,
                    width,
                    height,
                    orbit,
                    progressive,
                    &views,
                ) {
                    Ok(job) => {
                        cancel_current(&current);
                        let flag = Arc::new(AtomicBool::new(false));
                        if let Ok(mut c) = current.lock() {
                            *c = Some(Arc::clone(&flag));
                        }
                        if cmd_tx.send(Command::Render(job, flag)).is_err() {
                            break 'conn;
                        }
                    }
                    Err(message) => {
                        let m = json!({"type": "error", "id": id, "message": message});
                        if ws.send(Message::text(m.to_string())).is_err() {
                            break 'conn;
                        }
                    }
                },
                Ok(Request::Save { view, format }) => {
                    if cmd_tx.send(Command::Save { view, format }).is_err() {
                        break 'conn;
                    }
                }
                Err(message) => {
                    let m = json!({"type": "error", "message": message});
                    if ws.send(Message::text(m.to_string())).is_err() {
                        break 'conn;
                    }
                }
            },
            Ok(Message::Binary(_)) => {
                let m = json!({"type": "error", "message": "binary messages are not understood"});
                if ws.send(Message::text(m.to_string())).is_err() {
                    break 'conn;
                }
            }
            Ok(Message::Close(_)) => break 'conn,
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(tungstenite::Error::Capacity(e)) => {
                // An oversized message: tell the page, then drop the
                // connection (the stream position is lost).
                let m = json!({"type": "error", "message": format!("message too large: {e}")});
                let _ = ws.send(Message::text(m.to_string()));
                break 'conn;
            }
            Err(_) => break 'conn,
        }
        loop {
            match out_rx.try_recv() {
                Ok(msg) => {
                    if ws.send(msg).is_err() {
                        break 'conn;
                    }
                }
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => break 'conn,
            }
        }
        if let Err(tungstenite::Error::Io(e)) = ws.flush()
            && !matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            )
        {
            break 'conn;
        }
    }
    cancel_current(&current);
    drop(cmd_tx);
    let _ = ws.close(None);
    let _ = ws.flush();
}

/// The last finished render of each view, for saving.
#[derive(Default)]
struct Finished {
    films: [Option<(Film, chiaro::RenderSettings)>; 2],
}

fn worker(state: &State, rx: &Receiver<Command>, out: &Sender<Message>) {
    let mut finished = Finished::default();
    while let Ok(first) = rx.recv() {
        // Only the newest render matters; saves are answered in order.
        let mut pending = vec![first];
        while let Ok(c) = rx.try_recv() {
            pending.push(c);
        }
        let last_render = pending
            .iter()
            .rposition(|c| matches!(c, Command::Render(..)));
        for (i, cmd) in pending.into_iter().enumerate() {
            let ok = match cmd {
                Command::Render(job, flag) if Some(i) == last_render => {
                    render_job(state, &job, &flag, out, &mut finished)
                }
                Command::Render(..) => true,
                Command::Save { view, format } => save(state, &finished, view, &format, out),
            };
            if !ok {
                return;
            }
        }
    }
}

fn text(out: &Sender<Message>, v: serde_json::Value) -> bool {
    out.send(Message::text(v.to_string())).is_ok()
}

fn png_opts(s: &chiaro::RenderSettings) -> OutputOptions {
    OutputOptions {
        tonemap: s.tonemap,
        exposure: s.exposure,
        ..OutputOptions::default()
    }
}

/// Rows `y0..y1` of `film` as a PNG.
fn band_png(film: &Film, y0: u32, y1: u32, opts: &OutputOptions) -> Result<Vec<u8>, String> {
    let mut band = Film::new(film.width, y1 - y0);
    let a = film.index(0, y0);
    let b = a + band.color.len();
    band.color.copy_from_slice(&film.color[a..b]);
    band.depth.copy_from_slice(&film.depth[a..b]);
    band.normal.copy_from_slice(&film.normal[a..b]);
    encode_film(&band, ImageFormat::Png, opts)
}

/// Why a view's render stopped.
enum Stop {
    Render(chiaro::Error),
    Closed,
}

impl From<chiaro::Error> for Stop {
    fn from(e: chiaro::Error) -> Self {
        Stop::Render(e)
    }
}

/// Renders every view of `job`, sending bands, `done` messages and, for two
/// views, the difference image and metrics. Returns false when the
/// connection has gone.
fn render_job(
    _state: &State,
    job: &Job,
    flag: &Arc<AtomicBool>,
    out: &Sender<Message>,
    finished: &mut Finished,
) -> bool {
    let progress = JobProgress(Arc::clone(flag));
    let mut films = Vec::new();
    for (view, (scene, settings)) in job.scenes.iter().zip(&job.settings).enumerate() {
        let start = Instant::now();
        let opts = png_opts(settings);
        let mut first_band = true;
        let mut send_band = |film: &Film, y0: u32, y1: u32| -> Result<(), Stop> {
            let png = band_png(film, y0, y1, &opts).map_err(|m| {
                Stop::Render(chiaro::Error::Core(
                    chiaro_core::error::CoreError::Unsupported(m),
                ))
            })?;
            let header = FrameHeader {
                kind: "tile",
                id: job.id,
                view,
                x: 0,
                y: y0,
                w: film.width,
                h: y1 - y0,
                width: film.width,
                height: film.height,
                name: String::new(),
            };
            if first_band {
                first_band = false;
                let m = json!({"type": "first", "id": job.id, "view": view,
                    "ms": start.elapsed().as_secs_f64() * 1e3});
                if !text(out, m) {
                    return Err(Stop::Closed);
                }
            }
            out.send(Message::binary(encode_frame(&header, &png)))
                .map_err(|_| Stop::Closed)
        };
        let result = if job.progressive {
            render_in_bands(scene, settings, &progress, &mut send_band)
        } else {
            chiaro::render_with_stats(scene, settings, &progress)
                .map_err(Stop::from)
                .and_then(|(film, stats)| {
                    send_band(&film, 0, film.height)?;
                    Ok((film, stats))
                })
        };
        match result {
            Ok((film, stats)) => {
                let m = json!({
                    "type": "done", "id": job.id, "view": view,
                    "technique": settings.technique.name(),
                    "width": settings.width, "height": settings.height,
                    "samples": settings.samples,
                    "ms": start.elapsed().as_secs_f64() * 1e3,
                    "render_ms": stats.elapsed.as_secs_f64() * 1e3,
                    "rays": stats.rays, "triangles": stats.triangles,
                });
                if !text(out, m) {
                    return false;
                }
                films.push(film);
            }
            Err(Stop::Closed) => return false,
            Err(Stop::Render(chiaro::Error::Core(chiaro_core::error::CoreError::Cancelled))) => {
                return true;
            }
            Err(Stop::Render(e)) => {
                return text(
                    out,
                    json!({"type": "error", "id": job.id, "view": view, "message": e.to_string()}),
                );
            }
        }
        if flag.load(Ordering::Relaxed) {
            return true;
        }
    }
    for (i, film) in films.iter().enumerate() {
        if let Some(s) = job.settings.get(i) {
            finished.films[i] = Some((film.clone(), s.clone()));
        }
    }
    if films.len() == 2 {
        return send_comparison(job, &films[0], &films[1], out);
    }
    true
}

/// Sends the difference image of `a` against the reference `b` and the
/// numbers `chiaro compare` reports (RMSE, PSNR with peak 1, mean relative
/// error), all on linear radiance.
fn send_comparison(job: &Job, a: &Film, b: &Film, out: &Sender<Message>) -> bool {
    let (Ok(rmse), Ok(psnr), Ok(mre), Ok(diff)) = (
        metrics::rmse(a, b),
        metrics::psnr(a, b, 1.0),
        metrics::mean_relative_error(a, b),
        metrics::difference_image(a, b, metrics::ErrorKind::Absolute, None),
    ) else {
        return text(
            out,
            json!({"type": "error", "id": job.id, "message": "the two views differ in size"}),
        );
    };
    let psnr_json = if psnr.is_finite() {
        json!(psnr)
    } else {
        json!("inf")
    };
    if let Ok(png) = encode_film(&diff.film, ImageFormat::Png, &OutputOptions::default()) {
        let header = FrameHeader {
            kind: "diff",
            id: job.id,
            view: 2,
            x: 0,
            y: 0,
            w: diff.film.width,
            h: diff.film.height,
            width: diff.film.width,
            height: diff.film.height,
            name: String::new(),
        };
        if out
            .send(Message::binary(encode_frame(&header, &png)))
            .is_err()
        {
            return false;
        }
    }
    // Last, so that the page's "done" means every picture has arrived.
    let m = json!({
        "type": "metrics", "id": job.id,
        "rmse": rmse, "psnr": psnr_json, "mean_relative_error": mre,
        "diff_scale": diff.scale, "max_error": diff.max_error,
    });
    text(out, m)
}

/// Sends the last finished render of `view` as a PNG or EXR file frame.
fn save(
    state: &State,
    finished: &Finished,
    view: usize,
    format: &str,
    out: &Sender<Message>,
) -> bool {
    let fmt = match format {
        "png" => ImageFormat::Png,
        "exr" => ImageFormat::Exr,
        other => {
            return text(
                out,
                json!({"type": "error", "message": format!("cannot save as `{other}`: png or exr")}),
            );
        }
    };
    let Some(Some((film, settings))) = finished.films.get(view) else {
        return text(
            out,
            json!({"type": "error", "message": format!("view {view} has no finished render to save")}),
        );
    };
    match encode_film(film, fmt, &png_opts(settings)) {
        Ok(bytes) => {
            let technique: Technique = settings.technique;
            let header = FrameHeader {
                kind: "file",
                id: 0,
                view,
                x: 0,
                y: 0,
                w: film.width,
                h: film.height,
                width: film.width,
                height: film.height,
                name: format!("{}-{}.{format}", state.scene_name, technique.name()),
            };
            out.send(Message::binary(encode_frame(&header, &bytes)))
                .is_ok()
        }
        Err(m) => text(out, json!({"type": "error", "message": m})),
    }
}
