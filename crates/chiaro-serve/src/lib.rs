//! `chiaro serve`: a local web viewer for one scene, and a tev client.
//!
//! [`serve`] loads the scene it is given and serves, on loopback unless a
//! host is named, a plain HTML/JS/CSS page (embedded in the binary, no build
//! step) that starts on the scene's technique and renders it with any
//! other, shows bands as they arrive over a WebSocket, orbits the camera
//! (drafts while it moves: half resolution, one sample per pixel and per
//! area light; then a quick full-size pass and full quality when it stops),
//! puts two techniques side by side with the difference image and the
//! error numbers of `chiaro compare`, and saves PNG or EXR. `?still=1`
//! renders one full-quality picture and then sets `data-ready` on the
//! page's `<body>`, for screenshots. See [`protocol`] for the messages.
//!
//! The server reads no path from the page (only the scene given at start),
//! refuses sizes and sample counts beyond [`Limits`], and treats a closed
//! tab or a malformed request as that connection's problem only. Its
//! defences, each set in [`ServeOptions`]:
//!
//! - **A deadline per request**, not per read: the whole request head (and
//!   the WebSocket handshake) must arrive within `head_timeout` (10 s), or
//!   the connection gets `408` and is closed, however it trickles.
//! - **An idle timeout for WebSockets**: a session with no message from the
//!   page and no render running for `idle_timeout` (5 min) is closed (the
//!   page reconnects when next used). An idle session sleeps on a channel;
//!   it wakes only for bytes from the page or frames from its renderer.
//! - **Connection caps**: at most `max_per_address` (32) connections from
//!   one client address and `max_connections` (128) in all. A connection
//!   over a cap takes the place of the oldest one that is only waiting (a
//!   request head still arriving, or an idle WebSocket); when every one is
//!   busy it gets `503`. So slow or idle clients can never lock out a
//!   working one.
//! - **`Host` and `Origin` checks**: every request's `Host` and a
//!   WebSocket handshake's `Origin` (when sent: browsers always send it)
//!   must name the address served (`localhost` or an IP address, with its
//!   port); others get `403`, and a request with two `Host` or two
//!   `Origin` headers gets `400`. This stops other web sites from driving
//!   renders through the user's browser (cross-site WebSocket hijacking)
//!   and DNS-rebinding pages from reading the viewer.
//!
//! [`tev`] streams a render to a running tev viewer (pbrt-v4's
//! `--display-server`).
//!
//! HTTP requests are parsed with `httparse` and WebSockets framed with
//! `tungstenite` (the handshake's accept key from its
//! `derive_accept_key`); each connection has its own thread, and a
//! WebSocket also a reader and a render thread.

pub mod protocol;
mod session;
pub mod tev;

pub use protocol::Limits;

use chiaro::Scene;
use chiaro::scene::ReflectanceModel;
use std::collections::HashMap;
use std::io::{Read, Write};
use std::net::{IpAddr, Ipv4Addr, Shutdown, SocketAddr, TcpListener, TcpStream};
use std::path::Path;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};
use thiserror::Error;

/// The page, its script and its style, embedded at compile time.
const INDEX_HTML: &str = include_str!("../static/index.html");
const APP_JS: &str = include_str!("../static/app.js");
const STYLE_CSS: &str = include_str!("../static/style.css");

/// Largest HTTP request head accepted, bytes.
const MAX_HEAD_BYTES: usize = 16 * 1024;

/// How long one write to a client may block before the connection is
/// dropped (a client that stops reading).
const WRITE_TIMEOUT: Duration = Duration::from_secs(30);

/// What can go wrong starting the server.
#[derive(Debug, Error)]
pub enum ServeError {
    /// The scene could not be loaded.
    #[error(transparent)]
    Scene(#[from] chiaro::Error),
    /// The camera flags could not be met.
    #[error(transparent)]
    Camera(#[from] chiaro::camera::CameraError),
    /// The host is not an IP address.
    #[error("--host must be an IP address such as 127.0.0.1 or 0.0.0.0, not `{0}`")]
    BadHost(String),
    /// The address could not be bound (in use, no permission).
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// The underlying error.
        source: std::io::Error,
    },
}

/// How to serve.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// Address to listen on; `127.0.0.1` (loopback only) unless the user
    /// names another (`0.0.0.0` exposes the scene to the network). The
    /// string `localhost` is accepted for loopback.
    pub host: String,
    /// TCP port; 0 picks a free one (see [`Server::local_addr`]).
    pub port: u16,
    /// What a page may ask for.
    pub limits: Limits,
    /// Most simultaneous connections (HTTP and WebSocket together).
    pub max_connections: usize,
    /// Most simultaneous connections from one client IP address.
    pub max_per_address: usize,
    /// Time allowed for a whole request head (or WebSocket handshake) to
    /// arrive, from the connection's acceptance.
    pub head_timeout: Duration,
    /// A WebSocket with no message from the page and no render running for
    /// this long is closed.
    pub idle_timeout: Duration,
    /// The starting camera (`--camera`, `--eye`, ...), applied to a scene
    /// loaded by [`Server::bind`].
    pub camera: chiaro::camera::CameraChoice,
}

impl Default for ServeOptions {
    fn default() -> Self {
        Self {
            host: "127.0.0.1".into(),
            port: 8080,
            limits: Limits::default(),
            max_connections: 128,
            max_per_address: 32,
            head_timeout: Duration::from_secs(10),
            idle_timeout: Duration::from_secs(300),
            camera: chiaro::camera::CameraChoice::default(),
        }
    }
}

/// Parses `--host`: an IP address, or `localhost`.
///
/// # Errors
/// [`ServeError::BadHost`] for anything else (host names are not resolved,
/// so a name can never silently bind a public interface).
pub fn parse_host(host: &str) -> Result<IpAddr, ServeError> {
    if host.eq_ignore_ascii_case("localhost") {
        return Ok(IpAddr::V4(Ipv4Addr::LOCALHOST));
    }
    host.parse().map_err(|_| ServeError::BadHost(host.into()))
}

/// Whether a `Host` header value (`name[:port]`) names the address `served`:
/// `localhost` when serving loopback or every interface, the served IP
/// address, any loopback address when serving loopback, any IP address when
/// serving every interface; always with the served port (80 when absent).
/// Host names other than `localhost` are refused, which defeats DNS
/// rebinding (a foreign name resolving to this machine).
pub fn host_allowed(host: &str, served: SocketAddr) -> bool {
    let host = host.trim();
    let (name, port) = if let Some(rest) = host.strip_prefix('[') {
        let Some((inside, after)) = rest.split_once(']') else {
            return false;
        };
        let port = match after {
            "" => None,
            p => match p.strip_prefix(':') {
                Some(p) => Some(p),
                None => return false,
            },
        };
        (inside, port)
    } else {
        match host.rsplit_once(':') {
            Some((n, p)) => (n, Some(p)),
            None => (host, None),
        }
    };
    let port = match port {
        None => 80,
        Some(p) => match p.parse::<u16>() {
            Ok(p) => p,
            Err(_) => return false,
        },
    };
    if port != served.port() {
        return false;
    }
    let ip = served.ip();
    if name.eq_ignore_ascii_case("localhost") {
        return ip.is_loopback() || ip.is_unspecified();
    }
    match name.parse::<IpAddr>() {
        Ok(asked) => {
            asked == ip || ip.is_unspecified() || (ip.is_loopback() && asked.is_loopback())
        }
        Err(_) => false,
    }
}

/// `Host` or `Origin` when a request carries that header more than once
/// (names compared without case), `None` otherwise.
pub fn repeated_guard_header(headers: &[httparse::Header<'_>]) -> Option<&'static str> {
    ["Host", "Origin"].into_iter().find(|name| {
        headers
            .iter()
            .filter(|h| h.name.eq_ignore_ascii_case(name))
            .count()
            > 1
    })
}

/// Whether a WebSocket handshake's `Origin` header (absent for clients that
/// are not browsers) is the viewer's own page: `http://` and a host that
/// [`host_allowed`] accepts.
pub fn origin_allowed(origin: Option<&str>, served: SocketAddr) -> bool {
    match origin {
        None => true,
        Some(o) => o
            .trim()
            .strip_prefix("http://")
            .is_some_and(|h| !h.contains('/') && host_allowed(h, served)),
    }
}

/// What a connection is doing, which decides whether a newer connection
/// may take its place when a cap is reached.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum Phase {
    /// Its request head is still arriving.
    Head = 0,
    /// Answering a request, or a WebSocket with a render running.
    Busy = 1,
    /// A WebSocket waiting for the page.
    Idle = 2,
}

/// One open connection, as the registry sees it.
#[derive(Debug)]
struct Conn {
    addr: IpAddr,
    opened: Instant,
    phase: Arc<AtomicU8>,
    /// A handle on the socket, to shut it down when the connection is shed.
    stream: TcpStream,
}

/// What every connection shares.
#[derive(Debug)]
pub(crate) struct State {
    pub(crate) scene: Scene,
    pub(crate) scene_name: String,
    pub(crate) limits: Limits,
    served: SocketAddr,
    max_connections: usize,
    max_per_address: usize,
    head_timeout: Duration,
    pub(crate) idle_timeout: Duration,
    conns: Mutex<HashMap<u64, Conn>>,
    next_id: AtomicU64,
    /// Times a WebSocket session woke up (see [`ServerHandle::session_wakeups`]).
    pub(crate) session_wakeups: AtomicU64,
    /// The scene with each illumination model replacing every material's
    /// (a view's `model`), made when a page first asks for it and kept for
    /// the server's life, so that sessions keep what they prepare from it
    /// between frames ([`chiaro::FrameCache`]).
    models: [OnceLock<Scene>; 3],
}

/// A registered connection; dropping it unregisters it.
#[derive(Debug)]
pub(crate) struct ConnGuard {
    state: Arc<State>,
    id: u64,
    phase: Arc<AtomicU8>,
}

impl ConnGuard {
    pub(crate) fn set_phase(&self, phase: Phase) {
        self.phase.store(phase as u8, Ordering::SeqCst);
    }
}

impl Drop for ConnGuard {
    fn drop(&mut self) {
        if let Ok(mut conns) = self.state.conns.lock() {
            conns.remove(&self.id);
        }
    }
}

impl State {
    /// The scene a view with illumination model `model` renders (`None`:
    /// the scene's own models).
    pub(crate) fn scene_with(&self, model: Option<ReflectanceModel>) -> &Scene {
        let Some(m) = model else {
            return &self.scene;
        };
        let i = match m {
            ReflectanceModel::Phong => 0,
            ReflectanceModel::Blinn => 1,
            ReflectanceModel::TorranceSparrow => 2,
        };
        self.models[i].get_or_init(|| protocol::with_model(&self.scene, m))
    }

    /// Registers a new connection from `addr`, shedding the oldest waiting
    /// connection (from the same address when that address is at its cap)
    /// if a cap is reached. `None` when every candidate is busy.
    fn admit(self: &Arc<Self>, stream: &TcpStream, addr: IpAddr) -> Option<ConnGuard> {
        let handle = stream.try_clone().ok()?;
        let mut conns = self.conns.lock().ok()?;
        let from_addr = conns.values().filter(|c| c.addr == addr).count();
        let victim_pool: Option<bool> = if from_addr >= self.max_per_address {
            Some(true)
        } else if conns.len() >= self.max_connections {
            Some(false)
        } else {
            None
        };
        if let Some(same_addr) = victim_pool {
            let victim = conns
                .iter()
                .filter(|(_, c)| !same_addr || c.addr == addr)
                .filter(|(_, c)| c.phase.load(Ordering::SeqCst) != Phase::Busy as u8)
                .min_by_key(|(_, c)| c.opened)
                .map(|(id, _)| *id)?;
            if let Some(c) = conns.remove(&victim) {
                let _ = c.stream.shutdown(Shutdown::Both);
            }
        }
        let id = self.next_id.fetch_add(1, Ordering::SeqCst);
        let phase = Arc::new(AtomicU8::new(Phase::Head as u8));
        conns.insert(
            id,
            Conn {
                addr,
                opened: Instant::now(),
                phase: Arc::clone(&phase),
                stream: handle,
            },
        );
        Some(ConnGuard {
            state: Arc::clone(self),
            id,
            phase,
        })
    }
}

/// A bound server, not yet accepting.
#[derive(Debug)]
pub struct Server {
    listener: TcpListener,
    state: Arc<State>,
}

/// Read-only counters of a running [`Server`], for monitoring and tests.
#[derive(Debug, Clone)]
pub struct ServerHandle(Arc<State>);

impl ServerHandle {
    /// Connections open now (HTTP and WebSocket).
    pub fn open_connections(&self) -> usize {
        self.0.conns.lock().map(|c| c.len()).unwrap_or(0)
    }

    /// How many times WebSocket sessions have woken up in all: once per
    /// message from a page, frame to a page or finished render, never
    /// while idle.
    pub fn session_wakeups(&self) -> u64 {
        self.0.session_wakeups.load(Ordering::SeqCst)
    }
}

impl Server {
    /// Loads the scene at `scene_path` and binds the address of `opts`.
    ///
    /// # Errors
    /// [`ServeError::Scene`] if the scene does not load,
    /// [`ServeError::BadHost`] or [`ServeError::Bind`].
    pub fn bind(scene_path: &Path, opts: &ServeOptions) -> Result<Self, ServeError> {
        let mut loaded = chiaro::io::load_scene(scene_path).map_err(chiaro::Error::from)?;
        for w in &loaded.warnings {
            eprintln!("warning: {w}");
        }
        let aspect = loaded.scene.render.aspect();
        chiaro::camera::apply_camera(&mut loaded.scene, &opts.camera, aspect)?;
        let name = scene_path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into());
        Self::bind_scene(loaded.scene, &name, opts)
    }

    /// Binds the address of `opts` to serve an already loaded `scene`
    /// called `name` (used in saved file names).
    ///
    /// # Errors
    /// [`ServeError::BadHost`] or [`ServeError::Bind`].
    pub fn bind_scene(scene: Scene, name: &str, opts: &ServeOptions) -> Result<Self, ServeError> {
        let ip = parse_host(&opts.host)?;
        let addr = SocketAddr::new(ip, opts.port);
        let listener =
            TcpListener::bind(addr).map_err(|source| ServeError::Bind { addr, source })?;
        let served = listener
            .local_addr()
            .map_err(|source| ServeError::Bind { addr, source })?;
        let scene_name: String = name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        Ok(Self {
            listener,
            state: Arc::new(State {
                scene,
                scene_name,
                limits: opts.limits,
                served,
                max_connections: opts.max_connections.max(1),
                max_per_address: opts.max_per_address.max(1),
                head_timeout: opts.head_timeout,
                idle_timeout: opts.idle_timeout,
                conns: Mutex::new(HashMap::new()),
                next_id: AtomicU64::new(0),
                session_wakeups: AtomicU64::new(0),
                models: Default::default(),
            }),
        })
    }

    /// The address actually bound (the port chosen when 0 was asked).
    ///
    /// # Errors
    /// The operating system's error, if the socket has none.
    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.listener.local_addr()
    }

    /// Counters of this server that stay readable while it runs.
    pub fn handle(&self) -> ServerHandle {
        ServerHandle(Arc::clone(&self.state))
    }

    /// Runs the server ([`Server::run`]) on a thread of its own and returns
    /// the address it listens on: for tests, benchmarks and programs that
    /// go on while it serves.
    ///
    /// # Errors
    /// The operating system's error, if the socket has no address.
    pub fn spawn(self) -> std::io::Result<SocketAddr> {
        let addr = self.local_addr()?;
        std::thread::spawn(move || self.run());
        Ok(addr)
    }

    /// Accepts connections until the process ends; each is served on its
    /// own thread, so one slow or broken client never blocks another.
    pub fn run(self) {
        for stream in self.listener.incoming() {
            let Ok(mut stream) = stream else { continue };
            let Ok(peer) = stream.peer_addr() else {
                continue;
            };
            let Some(guard) = self.state.admit(&stream, peer.ip()) else {
                let _ = stream.set_write_timeout(Some(Duration::from_secs(1)));
                let _ = respond(&mut stream, 503, "text/plain", b"too many connections\n");
                continue;
            };
            let accepted = Instant::now();
            let state = Arc::clone(&self.state);
            let _ = std::thread::Builder::new()
                .name("chiaro-serve-conn".into())
                .spawn(move || handle_connection(stream, &state, &guard, accepted));
        }
    }
}

/// `chiaro serve SCENE`: loads the scene, listens on `opts.host:opts.port`,
/// prints the URL on stderr, and serves until the process ends.
///
/// # Errors
/// See [`Server::bind`]; serving itself does not fail (a broken connection
/// only ends that connection).
pub fn serve(scene_path: &Path, opts: ServeOptions) -> Result<(), ServeError> {
    let server = Server::bind(scene_path, &opts)?;
    let addr = server.local_addr().map_err(|source| ServeError::Bind {
        addr: SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), opts.port),
        source,
    })?;
    if !addr.ip().is_loopback() {
        eprintln!(
            "warning: listening on {addr}, reachable from other machines; the scene and the CPU are shared with anyone who connects"
        );
    }
    let shown = if addr.ip().is_unspecified() {
        SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), addr.port())
    } else {
        addr
    };
    eprintln!("chiaro serve: {} on http://{shown}/", scene_path.display());
    server.run();
    Ok(())
}

/// Writes a complete HTTP/1.1 response and closes the exchange.
fn respond(
    stream: &mut TcpStream,
    status: u16,
    content_type: &str,
    body: &[u8],
) -> std::io::Result<()> {
    let reason = match status {
        200 => "OK",
        204 => "No Content",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        431 => "Request Header Fields Too Large",
        503 => "Service Unavailable",
        _ => "Error",
    };
    let head = format!(
        "HTTP/1.1 {status} {reason}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes())?;
    stream.write_all(body)?;
    stream.flush()
}

/// Reads the request head (up to the blank line) by `deadline`. Returns the
/// bytes, or `None` on close, error, a missed deadline (then a 408 has been
/// sent) or a head over [`MAX_HEAD_BYTES`] (then a 431 has been sent).
fn read_head(stream: &mut TcpStream, deadline: Instant) -> Option<Vec<u8>> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() || stream.set_read_timeout(Some(left)).is_err() {
            let _ = respond(stream, 408, "text/plain", b"request head too slow\n");
            return None;
        }
        let n = match stream.read(&mut chunk) {
            Ok(0) => return None,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                let _ = respond(stream, 408, "text/plain", b"request head too slow\n");
                return None;
            }
            Err(_) => return None,
        };
        buf.extend_from_slice(&chunk[..n]);
        if buf.windows(4).any(|w| w == b"\r\n\r\n") {
            return Some(buf);
        }
        if buf.len() > MAX_HEAD_BYTES {
            let _ = respond(stream, 431, "text/plain", b"request head too large\n");
            return None;
        }
    }
}

fn handle_connection(
    mut stream: TcpStream,
    state: &Arc<State>,
    conn: &ConnGuard,
    accepted: Instant,
) {
    let deadline = accepted + state.head_timeout;
    let _ = stream.set_write_timeout(Some(WRITE_TIMEOUT));
    let Some(head) = read_head(&mut stream, deadline) else {
        return;
    };
    conn.set_phase(Phase::Busy);
    let mut headers = [httparse::EMPTY_HEADER; 64];
    let mut req = httparse::Request::new(&mut headers);
    let Ok(httparse::Status::Complete(_)) = req.parse(&head) else {
        let _ = respond(&mut stream, 400, "text/plain", b"malformed request\n");
        return;
    };
    let header = |name: &str| {
        req.headers
            .iter()
            .find(|h| h.name.eq_ignore_ascii_case(name))
            .and_then(|h| std::str::from_utf8(h.value).ok())
    };
    // Two `Host` (RFC 9112 section 3.2: answered with 400) or two `Origin`
    // headers: the checks below read one, another part of the stack might
    // read the other.
    if let Some(name) = repeated_guard_header(req.headers) {
        let body = format!("more than one {name} header\n");
        let _ = respond(&mut stream, 400, "text/plain", body.as_bytes());
        return;
    }
    if !header("host").is_some_and(|h| host_allowed(h, state.served)) {
        let _ = respond(
            &mut stream,
            403,
            "text/plain",
            b"the Host header does not name the address this viewer serves\n",
        );
        return;
    }
    let method = req.method.unwrap_or("");
    let path = req.path.unwrap_or("/");
    let path = path.split('?').next().unwrap_or("/");
    if method != "GET" {
        let _ = respond(&mut stream, 405, "text/plain", b"only GET is served\n");
        return;
    }
    match path {
        "/" | "/index.html" => {
            let _ = respond(
                &mut stream,
                200,
                "text/html; charset=utf-8",
                INDEX_HTML.as_bytes(),
            );
        }
        "/app.js" => {
            let _ = respond(
                &mut stream,
                200,
                "text/javascript; charset=utf-8",
                APP_JS.as_bytes(),
            );
        }
        "/style.css" => {
            let _ = respond(
                &mut stream,
                200,
                "text/css; charset=utf-8",
                STYLE_CSS.as_bytes(),
            );
        }
        "/api/info" => {
            let body = session::info_json(state);
            let _ = respond(&mut stream, 200, "application/json", body.as_bytes());
        }
        "/ws" => {
            if !origin_allowed(header("origin"), state.served) {
                let _ = respond(
                    &mut stream,
                    403,
                    "text/plain",
                    b"WebSocket from another site refused\n",
                );
                return;
            }
            let upgrade = header("upgrade").is_some_and(|u| u.eq_ignore_ascii_case("websocket"));
            let key = header("sec-websocket-key");
            match (upgrade, key) {
                (true, Some(key)) => {
                    let accept = tungstenite::handshake::derive_accept_key(key.trim().as_bytes());
                    let reply = format!(
                        "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Accept: {accept}\r\n\r\n"
                    );
                    // The handshake's reply is bound by the same deadline.
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() || stream.set_write_timeout(Some(left)).is_err() {
                        return;
                    }
                    if stream.write_all(reply.as_bytes()).is_ok() {
                        let _ = stream.set_write_timeout(Some(WRITE_TIMEOUT));
                        session::run(stream, Arc::clone(state), conn);
                    }
                }
                _ => {
                    let _ = respond(
                        &mut stream,
                        400,
                        "text/plain",
                        b"expected a WebSocket upgrade\n",
                    );
                }
            }
        }
        "/favicon.ico" => {
            let _ = respond(&mut stream, 204, "image/x-icon", b"");
        }
        _ => {
            let _ = respond(&mut stream, 404, "text/plain", b"not found\n");
        }
    }
}
