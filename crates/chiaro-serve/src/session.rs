//! One WebSocket connection: a reader thread that forwards the page's
//! bytes, a render worker that renders the latest request (cancelling the
//! one before it), and the session loop that owns the WebSocket and sleeps
//! on one channel fed by both until there is something to do. The worker
//! renders every frame through [`chiaro::render_frame`] with a
//! [`FrameCache`] per scene it shows, so that orbiting redoes only what the
//! camera changes.

use crate::protocol::{FrameHeader, Job, Request, draft_settings, encode_frame, make_job};
use crate::tev::render_in_bands;
use crate::{ConnGuard, Phase, State};
use chiaro::io::output::{ImageFormat, OutputOptions, encode_film};
use chiaro::scene::{Camera, ReflectanceModel};
use chiaro::{Film, FrameCache, Progress, RenderSettings, Scene, Technique};
use chiaro_tools::metrics;
use serde_json::json;
use std::io::{Read, Write};
use std::net::{Shutdown, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, channel, sync_channel};
use std::time::Instant;
use tungstenite::protocol::frame::CloseFrame;
use tungstenite::protocol::frame::coding::CloseCode;
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
        "techniques": chiaro::Technique::ALL.iter().map(|t| t.name()).collect::<Vec<_>>(),
        "shadows": ["scene", "none", "map", "volume", "ray", "object", "scanline"],
        "transparency": ["scene", "interpolated", "screen-door", "filtered"],
        "models": ["scene", "phong", "blinn", "torrance-sparrow"],
        "limits": state.limits,
        "triangles": state.scene.triangle_count(),
    })
    .to_string()
}

/// The worker's progress, one for the connection's life (the frame caches
/// borrow it): the running job is cancelled once the session has counted a
/// newer request (or the connection's end) in `latest` than the job's own
/// number, `current`.
struct JobProgress {
    latest: Arc<AtomicU64>,
    current: AtomicU64,
}

impl Progress for JobProgress {
    fn begin(&self, _stage: &str, _total: u64) {}
    fn advance(&self, _n: u64) {}
    fn cancelled(&self) -> bool {
        self.latest.load(Ordering::Relaxed) != self.current.load(Ordering::Relaxed)
    }
}

enum Command {
    /// A job and its number in the session's count of requests.
    Render(Job, u64),
    Save {
        view: usize,
        format: String,
    },
}

/// What wakes the session loop.
enum Event {
    /// Bytes from the page.
    Net(Vec<u8>),
    /// The page closed the connection (or it broke).
    NetClosed,
    /// A message for the page from the worker.
    Out(Message),
    /// The worker handled this many commands.
    Finished(usize),
}

/// The WebSocket's stream: reads come from the bytes the reader thread
/// forwarded (`WouldBlock` when there are none yet), writes go to the
/// socket.
struct Duplex {
    inbox: Vec<u8>,
    pos: usize,
    out: TcpStream,
}

impl Duplex {
    fn feed(&mut self, bytes: &[u8]) {
        self.inbox.drain(..self.pos);
        self.pos = 0;
        self.inbox.extend_from_slice(bytes);
    }
}

impl Read for Duplex {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let left = &self.inbox[self.pos..];
        if left.is_empty() {
            return Err(std::io::ErrorKind::WouldBlock.into());
        }
        let n = left.len().min(buf.len());
        buf[..n].copy_from_slice(&left[..n]);
        self.pos += n;
        Ok(n)
    }
}

impl Write for Duplex {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.out.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

/// Forwards what the page sends until it closes or the session ends.
fn reader(mut stream: TcpStream, tx: &SyncSender<Event>) {
    let mut buf = vec![0u8; 16 * 1024];
    loop {
        match stream.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                if tx.send(Event::Net(buf[..n].to_vec())).is_err() {
                    return;
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(_) => break,
        }
    }
    let _ = tx.send(Event::NetClosed);
}

/// The session loop's state besides the WebSocket.
struct Session<'a> {
    state: &'a State,
    conn: &'a ConnGuard,
    commands: std::sync::mpsc::Sender<Command>,
    /// Counts render requests and the connection's end: a job whose number
    /// is behind it is cancelled ([`JobProgress`]).
    latest: Arc<AtomicU64>,
    /// Commands sent to the worker and not yet finished.
    pending: usize,
}

impl Session<'_> {
    /// Cancels the running job; returns the number of the next one.
    fn cancel_current(&mut self) -> u64 {
        self.latest.fetch_add(1, Ordering::Relaxed) + 1
    }

    fn command(&mut self, c: Command) -> bool {
        self.pending += 1;
        self.conn.set_phase(Phase::Busy);
        self.commands.send(c).is_ok()
    }

    /// Answers one message from the page; false when the connection must end.
    fn on_message(&mut self, ws: &mut WebSocket<Duplex>, msg: Message) -> bool {
        let error = |ws: &mut WebSocket<Duplex>, v: serde_json::Value| {
            ws.send(Message::text(v.to_string())).is_ok()
        };
        match msg {
            Message::Text(text) => match Request::parse(text.as_str()) {
                Ok(Request::Render {
                    id,
                    width,
                    height,
                    orbit,
                    progressive,
                    refine,
                    views,
                }) => match make_job(
                    &self.state.scene,
                    &self.state.limits,
                    id,
                    width,
                    height,
                    orbit,
                    progressive,
                    refine,
                    &views,
                ) {
                    Ok(job) => {
                        let number = self.cancel_current();
                        self.command(Command::Render(job, number))
                    }
                    Err(message) => {
                        error(ws, json!({"type": "error", "id": id, "message": message}))
                    }
                },
                Ok(Request::Save { view, format }) => self.command(Command::Save { view, format }),
                Err(message) => error(ws, json!({"type": "error", "message": message})),
            },
            Message::Binary(_) => error(
                ws,
                json!({"type": "error", "message": "binary messages are not understood"}),
            ),
            Message::Close(_) => false,
            _ => true,
        }
    }
}

/// Serves one upgraded connection until it closes, breaks, or stays idle
/// for the server's idle timeout.
pub(crate) fn run(stream: TcpStream, state: Arc<State>, conn: &ConnGuard) {
    let _ = stream.set_read_timeout(None);
    let _ = stream.set_nodelay(true);
    let (Ok(read_half), Ok(closer)) = (stream.try_clone(), stream.try_clone()) else {
        return;
    };
    // Bounded, so that neither a flooding page nor a fast renderer queues
    // more than a few messages ahead of the socket.
    let (events, inbox) = sync_channel::<Event>(16);
    let net_events = events.clone();
    let spawned_reader = std::thread::Builder::new()
        .name("chiaro-serve-read".into())
        .spawn(move || reader(read_half, &net_events));
    let (cmd_tx, cmd_rx) = channel::<Command>();
    let worker_state = Arc::clone(&state);
    let latest = Arc::new(AtomicU64::new(0));
    let worker_latest = Arc::clone(&latest);
    let spawned_worker = std::thread::Builder::new()
        .name("chiaro-serve-render".into())
        .spawn(move || worker(&worker_state, &cmd_rx, &events, worker_latest));
    if spawned_reader.is_err() || spawned_worker.is_err() {
        let _ = closer.shutdown(Shutdown::Both);
        return;
    }
    let config = WebSocketConfig::default()
        .max_message_size(Some(state.limits.max_message_bytes))
        .max_frame_size(Some(state.limits.max_message_bytes));
    let duplex = Duplex {
        inbox: Vec::new(),
        pos: 0,
        out: stream,
    };
    let mut ws = WebSocket::from_raw_socket(duplex, Role::Server, Some(config));
    let mut session = Session {
        state: &state,
        conn,
        commands: cmd_tx,
        latest,
        pending: 0,
    };
    conn.set_phase(Phase::Idle);
    let mut last_activity = Instant::now();
    'conn: loop {
        let event = if session.pending == 0 {
            let deadline = last_activity + state.idle_timeout;
            match inbox.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                Ok(e) => e,
                Err(RecvTimeoutError::Timeout) => {
                    let _ = ws.close(Some(CloseFrame {
                        code: CloseCode::Away,
                        reason: "idle".into(),
                    }));
                    break 'conn;
                }
                Err(RecvTimeoutError::Disconnected) => break 'conn,
            }
        } else {
            match inbox.recv() {
                Ok(e) => e,
                Err(_) => break 'conn,
            }
        };
        state.session_wakeups.fetch_add(1, Ordering::Relaxed);
        match event {
            Event::Net(bytes) => {
                last_activity = Instant::now();
                ws.get_mut().feed(&bytes);
                loop {
                    match ws.read() {
                        Ok(msg) => {
                            if !session.on_message(&mut ws, msg) {
                                break 'conn;
                            }
                        }
                        Err(tungstenite::Error::Io(e))
                            if e.kind() == std::io::ErrorKind::WouldBlock =>
                        {
                            break;
                        }
                        Err(tungstenite::Error::Capacity(e)) => {
                            // An oversized message: tell the page, then drop
                            // the connection (the stream position is lost).
                            let m = json!({"type": "error", "message": format!("message too large: {e}")});
                            let _ = ws.send(Message::text(m.to_string()));
                            break 'conn;
                        }
                        Err(_) => break 'conn,
                    }
                }
            }
            Event::NetClosed => break 'conn,
            Event::Out(msg) => {
                if ws.send(msg).is_err() {
                    break 'conn;
                }
            }
            Event::Finished(n) => {
                session.pending = session.pending.saturating_sub(n);
                if session.pending == 0 {
                    last_activity = Instant::now();
                    conn.set_phase(Phase::Idle);
                }
            }
        }
    }
    session.cancel_current();
    drop(session);
    let _ = ws.flush();
    let _ = closer.shutdown(Shutdown::Both);
}

/// The last finished render of each view, for saving.
#[derive(Default)]
struct Finished {
    films: [Option<(Film, chiaro::RenderSettings)>; 2],
}

/// What the worker keeps between jobs: a frame cache per scene the last
/// job showed (the scene's own, or with a view's illumination model), and
/// the radiosity solutions solved on this connection (reported in `done`).
struct Frames<'w> {
    caches: Vec<(Option<ReflectanceModel>, FrameCache<'w>)>,
    solves: u64,
}

impl<'w> Frames<'w> {
    /// Keeps the caches of the scenes `job` shows, dropping the others.
    fn keep_for(&mut self, job: &Job) {
        self.caches.retain(|(m, _)| job.models.contains(m));
        for m in &job.models {
            if !self.caches.iter().any(|(k, _)| k == m) {
                self.caches.push((*m, FrameCache::new()));
            }
        }
    }

    /// [`chiaro::render_frame`] of `scene` (with illumination model
    /// `model`) through the cache of that scene, counting the radiosity
    /// solves.
    fn render(
        &mut self,
        model: Option<ReflectanceModel>,
        scene: &'w Scene,
        settings: &RenderSettings,
        camera: &Camera,
        progress: &'w dyn Progress,
    ) -> Result<(Film, chiaro::RenderStats), chiaro::Error> {
        let i = match self.caches.iter().position(|(k, _)| *k == model) {
            Some(i) => i,
            None => {
                self.caches.push((model, FrameCache::new()));
                self.caches.len() - 1
            }
        };
        let cache = &mut self.caches[i].1;
        let had = cache.holds_solution(&settings.radiosity);
        let result = chiaro::render_frame(scene, settings, camera, progress, cache);
        if settings.technique.solves_radiosity()
            && !had
            && cache.holds_solution(&settings.radiosity)
        {
            self.solves += 1;
        }
        result
    }
}

fn worker(state: &State, rx: &Receiver<Command>, out: &SyncSender<Event>, latest: Arc<AtomicU64>) {
    let progress = JobProgress {
        latest,
        current: AtomicU64::new(0),
    };
    let mut finished = Finished::default();
    let mut frames = Frames {
        caches: Vec::new(),
        solves: 0,
    };
    while let Ok(first) = rx.recv() {
        // Only the newest render matters; saves are answered in order.
        let mut pending = vec![first];
        while let Ok(c) = rx.try_recv() {
            pending.push(c);
        }
        let n = pending.len();
        let last_render = pending
            .iter()
            .rposition(|c| matches!(c, Command::Render(..)));
        for (i, cmd) in pending.into_iter().enumerate() {
            let ok = match cmd {
                Command::Render(job, number) if Some(i) == last_render => {
                    progress.current.store(number, Ordering::Relaxed);
                    frames.keep_for(&job);
                    render_job(state, &job, &progress, out, &mut finished, &mut frames)
                }
                Command::Render(..) => true,
                Command::Save { view, format } => save(state, &finished, view, &format, out),
            };
            if !ok {
                return;
            }
        }
        if out.send(Event::Finished(n)).is_err() {
            return;
        }
    }
}

fn send(out: &SyncSender<Event>, m: Message) -> bool {
    out.send(Event::Out(m)).is_ok()
}

fn text(out: &SyncSender<Event>, v: serde_json::Value) -> bool {
    send(out, Message::text(v.to_string()))
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

/// Renders one view, sending its picture (in bands when `progressive` and
/// the technique supports it).
fn render_view<'w>(
    state: &'w State,
    job: &Job,
    view: usize,
    settings: &RenderSettings,
    progressive: bool,
    progress: &'w dyn Progress,
    out: &SyncSender<Event>,
    frames: &mut Frames<'w>,
) -> Result<(Film, chiaro::RenderStats), Stop> {
    let model = job.models.get(view).copied().flatten();
    let scene = state.scene_with(model);
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
        send(out, Message::binary(encode_frame(&header, &png)))
            .then_some(())
            .ok_or(Stop::Closed)
    };
    let solves = matches!(settings.technique, Technique::Radiosity | Technique::Hybrid);
    let mut render = |s: &RenderSettings| frames.render(model, scene, s, &job.camera, progress);
    if progressive && !solves {
        render_in_bands(scene, settings, render, &mut send_band)
    } else {
        let (film, stats) = render(settings)?;
        send_band(&film, 0, film.height)?;
        Ok((film, stats))
    }
}

/// Renders every view of `job`, sending bands, `done` messages and, for two
/// views, the difference image and metrics; with `refine`, a quick draft
/// pass of every view first. Returns false when the connection has gone.
fn render_job<'w>(
    state: &'w State,
    job: &Job,
    progress: &'w JobProgress,
    out: &SyncSender<Event>,
    finished: &mut Finished,
    frames: &mut Frames<'w>,
) -> bool {
    let draft: Vec<RenderSettings> = job.settings.iter().map(draft_settings).collect();
    let passes: Vec<&[RenderSettings]> = if job.refine && draft != job.settings {
        vec![&draft, &job.settings]
    } else {
        vec![&job.settings]
    };
    for (k, pass) in passes.iter().enumerate() {
        let last = k + 1 == passes.len();
        if passes.len() > 1
            && !text(
                out,
                json!({"type": "pass", "id": job.id, "pass": k + 1, "of": passes.len()}),
            )
        {
            return false;
        }
        let mut films = Vec::new();
        for (view, settings) in pass.iter().enumerate() {
            let start = Instant::now();
            let progressive = job.progressive && last;
            match render_view(
                state,
                job,
                view,
                settings,
                progressive,
                progress,
                out,
                frames,
            ) {
                Ok((film, stats)) => {
                    if last {
                        let m = json!({
                            "type": "done", "id": job.id, "view": view,
                            "technique": settings.technique.name(),
                            "width": settings.width, "height": settings.height,
                            "samples": settings.samples,
                            "light_samples": settings.light_samples,
                            "ms": start.elapsed().as_secs_f64() * 1e3,
                            "render_ms": stats.elapsed.as_secs_f64() * 1e3,
                            "rays": stats.rays, "triangles": stats.triangles,
                            "radiosity_solves": frames.solves,
                        });
                        if !text(out, m) {
                            return false;
                        }
                    }
                    films.push(film);
                }
                Err(Stop::Closed) => return false,
                Err(Stop::Render(chiaro::Error::Core(
                    chiaro_core::error::CoreError::Cancelled,
                ))) => {
                    return true;
                }
                Err(Stop::Render(e)) => {
                    return text(
                        out,
                        json!({"type": "error", "id": job.id, "view": view, "message": e.to_string()}),
                    );
                }
            }
            if progress.cancelled() {
                return true;
            }
        }
        if last {
            for (i, film) in films.iter().enumerate() {
                if let Some(s) = job.settings.get(i) {
                    finished.films[i] = Some((film.clone(), s.clone()));
                }
            }
            if films.len() == 2 {
                return send_comparison(job, &films[0], &films[1], out);
            }
        }
    }
    true
}

/// Sends the ꟻLIP map of `a` against the reference `b` (the difference
/// image) and the numbers `chiaro compare` reports ([`metrics::Metrics`],
/// from the same code): relative MSE and ꟻLIP to rank by, the display
/// PSNR, and the linear RMSE, PSNR and mean relative error. An infinite
/// PSNR (identical pictures) is sent as `null`.
fn send_comparison(job: &Job, a: &Film, b: &Film, out: &SyncSender<Event>) -> bool {
    let Ok((m, flip_map)) = metrics::measure_with_flip_map(a, b) else {
        return text(
            out,
            json!({"type": "error", "id": job.id, "message": "the two views differ in size"}),
        );
    };
    if let Ok(png) = encode_film(&flip_map, ImageFormat::Png, &OutputOptions::default()) {
        let header = FrameHeader {
            kind: "diff",
            id: job.id,
            view: 2,
            x: 0,
            y: 0,
            w: flip_map.width,
            h: flip_map.height,
            width: flip_map.width,
            height: flip_map.height,
            name: String::new(),
        };
        if !send(out, Message::binary(encode_frame(&header, &png))) {
            return false;
        }
    }
    // Last, so that the page's "done" means every picture has arrived.
    let mut message = serde_json::to_value(m).unwrap_or_else(|_| json!({}));
    message["type"] = json!("metrics");
    message["id"] = json!(job.id);
    text(out, message)
}

/// Sends the last finished render of `view` as a PNG or EXR file frame.
fn save(
    state: &State,
    finished: &Finished,
    view: usize,
    format: &str,
    out: &SyncSender<Event>,
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
            send(out, Message::binary(encode_frame(&header, &bytes)))
        }
        Err(m) => text(out, json!({"type": "error", "message": m})),
    }
}
