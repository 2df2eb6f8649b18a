//! One WebSocket connection: a reader thread that forwards the page's
//! bytes, a render worker that renders the latest request (cancelling the
//! one before it), and the session loop that owns the WebSocket and sleeps
//! on one channel fed by both until there is something to do.

use crate::protocol::{FrameHeader, Job, Request, draft_settings, encode_frame, make_job};
use crate::tev::render_in_bands;
use crate::{ConnGuard, Phase, State};
use chiaro::RadiositySolution;
use chiaro::io::output::{ImageFormat, OutputOptions, encode_film};
use chiaro::{Film, Progress, RenderSettings, Scene, Technique};
use chiaro_tools::metrics;
use serde_json::json;
use std::io::{Read, Write};
use std::net::{Shutdown, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
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
    /// The running render's cancel flag.
    current: Option<Arc<AtomicBool>>,
    /// Commands sent to the worker and not yet finished.
    pending: usize,
}

impl Session<'_> {
    fn cancel_current(&mut self) {
        if let Some(flag) = self.current.take() {
            flag.store(true, Ordering::Relaxed);
        }
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
                        self.cancel_current();
                        let flag = Arc::new(AtomicBool::new(false));
                        self.current = Some(Arc::clone(&flag));
                        self.command(Command::Render(job, flag))
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
    let spawned_worker = std::thread::Builder::new()
        .name("chiaro-serve-render".into())
        .spawn(move || worker(&worker_state, &cmd_rx, &events));
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
        current: None,
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

fn worker(state: &State, rx: &Receiver<Command>, out: &SyncSender<Event>) {
    let mut finished = Finished::default();
    let mut solutions = SolutionCache::default();
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
                Command::Render(job, flag) if Some(i) == last_render => {
                    render_job(&job, &flag, out, &mut finished, &mut solutions)
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

/// The radiosity solution last solved on this connection, keyed by what it
/// depends on (the scene's geometry, materials and lights, and the
/// radiosity settings; not the camera), so that orbiting a radiosity or
/// hybrid render does not solve again.
#[derive(Default)]
struct SolutionCache {
    cached: Option<((u64, String), Arc<RadiositySolution>)>,
    /// Solutions solved on this connection (reported in `done`).
    solves: u64,
}

impl SolutionCache {
    /// [`chiaro::render_with_stats`], giving the render context the cached
    /// solution for the techniques that solve radiosity, and keeping the
    /// context's solution for the next frame.
    fn render(
        &mut self,
        scene: &Scene,
        settings: &RenderSettings,
        progress: &dyn Progress,
    ) -> Result<(Film, chiaro::RenderStats), chiaro::Error> {
        if !settings.technique.solves_radiosity() {
            return chiaro::render_with_stats(scene, settings, progress);
        }
        let key = (
            chiaro::radiosity_fingerprint(scene, 0.0),
            serde_json::to_string(&settings.radiosity).unwrap_or_default(),
        );
        let mut ctx = chiaro::RenderContext::new(scene, settings, progress)?;
        match self.cached.take() {
            Some((k, solution)) if k == key => ctx = ctx.with_solution(solution),
            _ => self.solves += 1,
        }
        let result = chiaro::render_with(&ctx, chiaro::renderer(settings.technique));
        if let Some(solution) = ctx.solved::<RadiositySolution>() {
            self.cached = Some((key, solution));
        }
        result
    }
}

/// Renders one view, sending its picture (in bands when `progressive` and
/// the technique supports it).
fn render_view(
    job: &Job,
    view: usize,
    scene: &Scene,
    settings: &RenderSettings,
    progressive: bool,
    progress: &dyn Progress,
    out: &SyncSender<Event>,
    solutions: &mut SolutionCache,
) -> Result<(Film, chiaro::RenderStats), Stop> {
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
    if progressive && !solves {
        render_in_bands(scene, settings, progress, &mut send_band)
    } else {
        let (film, stats) = solutions.render(scene, settings, progress)?;
        send_band(&film, 0, film.height)?;
        Ok((film, stats))
    }
}

/// Renders every view of `job`, sending bands, `done` messages and, for two
/// views, the difference image and metrics; with `refine`, a quick draft
/// pass of every view first. Returns false when the connection has gone.
fn render_job(
    job: &Job,
    flag: &Arc<AtomicBool>,
    out: &SyncSender<Event>,
    finished: &mut Finished,
    solutions: &mut SolutionCache,
) -> bool {
    let progress = JobProgress(Arc::clone(flag));
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
        for (view, (scene, settings)) in job.scenes.iter().zip(pass.iter()).enumerate() {
            let start = Instant::now();
            let progressive = job.progressive && last;
            match render_view(
                job,
                view,
                scene,
                settings,
                progressive,
                &progress,
                out,
                solutions,
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
                            "radiosity_solves": solutions.solves,
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
            if flag.load(Ordering::Relaxed) {
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
