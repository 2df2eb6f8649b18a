//! `chiaro serve`: a local web viewer for one scene, and a tev client.
//!
//! [`serve`] loads the scene it is given and serves, on loopback unless a
//! host is named, a plain HTML/JS/CSS page (embedded in the binary, no build
//! step) that renders the scene with any technique, shows bands as they
//! arrive over a WebSocket, orbits the camera (low resolution while moving,
//! full resolution when still), puts two techniques side by side with the
//! difference image and the error numbers of `chiaro compare`, and saves
//! PNG or EXR. See [`protocol`] for the messages.
//!
//! The server reads no path from the page (only the scene given at start),
//! refuses sizes and sample counts beyond [`Limits`], caps the number of
//! connections, times out slow requests, and treats a closed tab or a
//! malformed request as that connection's problem only.
//!
//! [`tev`] streams a render to a running tev viewer (pbrt-v4's
//! `--display-server`).
//!
//! HTTP requests are parsed with `httparse` and WebSockets framed with
//! `tungstenite` (the handshake's accept key from its
//! `derive_accept_key`); each connection has its own thread.

pub mod protocol;
mod session;
pub mod tev;

pub use protocol::Limits;

use chiaro::Scene;
use std::io::{Read, Write};
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;
use thiserror::Error;

/// The page, its script and its style, embedded at compile time.
const INDEX_HTML: &str = include_str!("../static/index.html");
const APP_JS: &str = include_str!("../static/app.js");
const STYLE_CSS: &str = include_str!("../static/style.css");

/// Largest HTTP request head accepted, bytes.
const MAX_HEAD_BYTES: usize = 16 * 1024;

/// What can go wrong starting the server.
#[derive(Debug, Error)]
pub enum ServeError {
    /// The scene could not be loaded.
    #[error(transparent)]
    Scene(#[from] chiaro::Error),
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
}

impl Default for ServeOptions {
    fn default() -> Self {
        Self {
            host: "127.0.0.1".into(),
            port: 8080,
            limits: Limits::default(),
            max_connections: 32,
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

/// What every connection shares.
#[derive(Debug)]
pub(crate) struct State {
    pub(crate) scene: Scene,
    pub(crate) scene_name: String,
    pub(crate) limits: Limits,
    connections: AtomicUsize,
    max_connections: usize,
}

/// A bound server, not yet accepting.
#[derive(Debug)]
pub struct Server {
    listener: TcpListener,
    state: Arc<State>,
}

impl Server {
    /// Loads the scene at `scene_path` and binds the address of `opts`.
    ///
    /// # Errors
    /// [`ServeError::Scene`] if the scene does not load,
    /// [`ServeError::BadHost`] or [`ServeError::Bind`].
    pub fn bind(scene_path: &Path, opts: &ServeOptions) -> Result<Self, ServeError> {
        let loaded = chiaro::io::load_scene(scene_path).map_err(chiaro::Error::from)?;
        for w in &loaded.warnings {
            eprintln!("warning: {w}");
        }
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
                connections: AtomicUsize::new(0),
                max_connections: opts.max_connections.max(1),
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

    /// Accepts connections until the process ends; each is served on its
    /// own thread, so one slow or broken client never blocks another.
    pub fn run(self) {
        for stream in self.listener.incoming() {
            let Ok(stream) = stream else { continue };
            let state = Arc::clone(&self.state);
            let n = state.connections.fetch_add(1, Ordering::SeqCst);
            if n >= state.max_connections {
                state.connections.fetch_sub(1, Ordering::SeqCst);
                let mut s = stream;
                let _ = respond(&mut s, 503, "text/plain", b"too many connections\n");
                continue;
            }
            let spawned = std::thread::Builder::new()
                .name("chiaro-serve-conn".into())
                .spawn(move || {
                    handle_connection(stream, &state);
                    state.connections.fetch_sub(1, Ordering::SeqCst);
                });
            if spawned.is_err() {
                self.state.connections.fetch_sub(1, Ordering::SeqCst);
            }
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
        404 => "Not Found",
        405 => "Method Not Allowed",
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

/// Reads the request head (up to the blank line). Returns the bytes, or
/// `None` on timeout, close, or a head over [`MAX_HEAD_BYTES`] (then a 431
/// has been sent).
fn read_head(stream: &mut TcpStream) -> Option<Vec<u8>> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    loop {
        let n = stream.read(&mut chunk).ok()?;
        if n == 0 {
            return None;
        }
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

fn handle_connection(mut stream: TcpStream, state: &Arc<State>) {
    let _ = stream.set_read_timeout(Some(Duration::from_secs(10)));
    let _ = stream.set_write_timeout(Some(Duration::from_secs(30)));
    let Some(head) = read_head(&mut stream) else {
        return;
    };
    let mut headers = [httparse::EMPTY_HEADER; 64];
    let mut req = httparse::Request::new(&mut headers);
    let Ok(httparse::Status::Complete(_)) = req.parse(&head) else {
        let _ = respond(&mut stream, 400, "text/plain", b"malformed request\n");
        return;
    };
    let method = req.method.unwrap_or("");
    let path = req.path.unwrap_or("/");
    let path = path.split('?').next().unwrap_or("/");
    if method != "GET" {
        let _ = respond(&mut stream, 405, "text/plain", b"only GET is served\n");
        return;
    }
    let header = |name: &str| {
        req.headers
            .iter()
            .find(|h| h.name.eq_ignore_ascii_case(name))
            .and_then(|h| std::str::from_utf8(h.value).ok())
    };
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
            let upgrade = header("upgrade").is_some_and(|u| u.eq_ignore_ascii_case("websocket"));
            let key = header("sec-websocket-key");
            match (upgrade, key) {
                (true, Some(key)) => {
                    let accept = tungstenite::handshake::derive_accept_key(key.trim().as_bytes());
                    let reply = format!(
                        "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Accept: {accept}\r\n\r\n"
                    );
                    if stream.write_all(reply.as_bytes()).is_ok() {
                        session::run(stream, Arc::clone(state));
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
