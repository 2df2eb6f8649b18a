//! `chiaro serve` under hostile or careless clients, on loopback only:
//! slow request heads (slowloris), idle WebSockets, cross-site handshakes
//! and foreign `Host` names, the per-address cap, the idle timeout, and an
//! idle session that sleeps. Every socket has a timeout and every loop a
//! bound, so no test can hang.

use chiaro_serve::{ServeOptions, Server, ServerHandle, host_allowed, origin_allowed};
use serde_json::{Value, json};
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::time::{Duration, Instant};
use tungstenite::{Message, WebSocket};

fn cornell() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.toml")
}

/// Starts a server for the Cornell box on a free loopback port.
fn start(opts: ServeOptions) -> (SocketAddr, ServerHandle) {
    let opts = ServeOptions { port: 0, ..opts };
    let server = Server::bind(&cornell(), &opts).expect("binds");
    let handle = server.handle();
    (server.spawn().expect("addr"), handle)
}

fn connect(addr: SocketAddr) -> TcpStream {
    let s = TcpStream::connect_timeout(&addr, Duration::from_secs(5)).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    s.set_write_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    s
}

/// Sends raw bytes and returns the whole response (bounded by the timeouts).
fn raw(addr: SocketAddr, request: &str) -> String {
    let mut s = connect(addr);
    s.write_all(request.as_bytes()).expect("write");
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    String::from_utf8_lossy(&out).into_owned()
}

/// Sends raw bytes and returns the response head only (an upgraded
/// WebSocket stays open after it).
fn raw_head(addr: SocketAddr, request: &str) -> String {
    let mut s = connect(addr);
    s.write_all(request.as_bytes()).expect("write");
    let mut out = Vec::new();
    let mut buf = [0u8; 512];
    while !out.windows(4).any(|w| w == b"\r\n\r\n") {
        match s.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => out.extend_from_slice(&buf[..n]),
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn get(addr: SocketAddr, path: &str) -> String {
    raw(
        addr,
        &format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\n\r\n"),
    )
}

type Ws = WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>;

fn ws(addr: SocketAddr) -> Ws {
    let (ws, _) = tungstenite::connect(format!("ws://{addr}/ws")).expect("websocket");
    if let tungstenite::stream::MaybeTlsStream::Plain(s) = ws.get_ref() {
        s.set_read_timeout(Some(Duration::from_secs(20)))
            .expect("timeout");
    }
    ws
}

/// Renders a small preview over a fresh WebSocket and waits for `done`.
fn render_once(addr: SocketAddr, id: u64) {
    let mut c = ws(addr);
    let m = json!({"type": "render", "id": id, "width": 32, "height": 32,
        "progressive": true, "views": [{"technique": "preview"}]});
    c.send(Message::text(m.to_string())).expect("send");
    for _ in 0..100 {
        match c.read().expect("a message before the timeout") {
            Message::Text(t) => {
                let v: Value = serde_json::from_str(t.as_str()).expect("JSON");
                assert_ne!(v["type"], "error", "{v}");
                if v["type"] == "done" {
                    assert_eq!(v["id"], id);
                    return;
                }
            }
            Message::Close(_) => panic!("closed before done"),
            _ => {}
        }
    }
    panic!("no done message");
}

/// Whether the server has closed `s`: a read gives end of file, a reset or
/// a response (a 408 for a late head), rather than timing out.
fn closed_by_server(s: &TcpStream, wait: Duration) -> bool {
    s.set_read_timeout(Some(wait)).expect("timeout");
    let mut buf = [0u8; 256];
    let mut reader = s;
    match reader.read(&mut buf) {
        // End of file (0) or a response's first bytes.
        Ok(n) => n <= buf.len(),
        Err(e) => !matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut),
    }
}

#[test]
fn slowloris_does_not_lock_out_a_normal_client() {
    let head_timeout = Duration::from_millis(1200);
    let (addr, handle) = start(ServeOptions {
        head_timeout,
        ..ServeOptions::default()
    });
    let opened = Instant::now();
    let mut slow: Vec<TcpStream> = (0..64)
        .map(|_| {
            let mut s = connect(addr);
            s.write_all(b"GET / HTTP/1.1\r\n").expect("write");
            s
        })
        .collect();
    // They keep sending a byte every 300 ms, far within any per-read
    // timeout, until past the head deadline.
    let trickle = std::thread::spawn(move || {
        let end = Instant::now() + Duration::from_millis(1600);
        while Instant::now() < end {
            for s in &mut slow {
                let _ = s.write_all(b"X");
            }
            std::thread::sleep(Duration::from_millis(300));
        }
        slow
    });
    std::thread::sleep(Duration::from_millis(300));
    let t = Instant::now();
    let page = get(addr, "/");
    assert!(page.starts_with("HTTP/1.1 200"), "{page}");
    render_once(addr, 1);
    assert!(
        t.elapsed() < Duration::from_secs(5),
        "the normal client waited {:?}",
        t.elapsed()
    );
    assert!(handle.open_connections() <= 32 + 1, "per-address cap");
    let slow = trickle.join().expect("trickle thread");
    // Past the deadline every slow connection has been closed (shed for a
    // newer one, or answered 408), though it never paused 2 s.
    assert!(opened.elapsed() > head_timeout);
    let still_open = slow
        .iter()
        .filter(|s| !closed_by_server(s, Duration::from_millis(1000)))
        .count();
    assert_eq!(still_open, 0, "slow heads outlived the 1.2 s deadline");
}

#[test]
fn a_trickled_head_gets_408_at_the_deadline() {
    let (addr, _) = start(ServeOptions {
        head_timeout: Duration::from_millis(800),
        ..ServeOptions::default()
    });
    let mut s = connect(addr);
    let t = Instant::now();
    s.write_all(b"GET / HTTP/1.1\r\n").expect("write");
    for _ in 0..4 {
        std::thread::sleep(Duration::from_millis(300));
        let _ = s.write_all(b"X");
    }
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    let reply = String::from_utf8_lossy(&out);
    assert!(reply.starts_with("HTTP/1.1 408"), "{reply}");
    let waited = t.elapsed();
    assert!(
        waited >= Duration::from_millis(700) && waited < Duration::from_secs(3),
        "{waited:?}"
    );
}

#[test]
fn idle_websockets_do_not_lock_out_a_normal_client_and_sleep() {
    let (addr, handle) = start(ServeOptions::default());
    let idle: Vec<Ws> = (0..64).map(|_| ws(addr)).collect();
    // Let the shed ones finish closing.
    std::thread::sleep(Duration::from_millis(300));
    assert!(
        handle.open_connections() <= 32,
        "{} open from one address",
        handle.open_connections()
    );
    // The idle sessions sleep: a half second without any wake-up (a 20 ms
    // poll would give about 25 per session). Up to three windows, in case
    // the shed sessions' last wake-ups fall into the first.
    let mut woke = Vec::new();
    for _ in 0..3 {
        let before = handle.session_wakeups();
        std::thread::sleep(Duration::from_millis(500));
        woke.push(handle.session_wakeups() - before);
        if woke.last() == Some(&0) {
            break;
        }
    }
    assert_eq!(woke.last(), Some(&0), "idle sessions woke up: {woke:?}");
    let before = handle.session_wakeups();
    let t = Instant::now();
    assert!(get(addr, "/api/info").starts_with("HTTP/1.1 200"));
    render_once(addr, 2);
    assert!(t.elapsed() < Duration::from_secs(5), "{:?}", t.elapsed());
    assert!(
        handle.session_wakeups() > before,
        "a render wakes its session"
    );
    drop(idle);
}

#[test]
fn cross_site_handshakes_and_foreign_hosts_get_403() {
    let (addr, _) = start(ServeOptions::default());
    let port = addr.port();
    let handshake = |host: &str, origin: Option<&str>| {
        let origin = origin
            .map(|o| format!("Origin: {o}\r\n"))
            .unwrap_or_default();
        raw_head(
            addr,
            &format!(
                "GET /ws HTTP/1.1\r\nHost: {host}\r\n{origin}Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
            ),
        )
    };
    let local = format!("127.0.0.1:{port}");
    for evil in [
        "http://evil.example.com",
        "https://evil.example.com",
        "null",
        &format!("http://evil.example.com:{port}"),
        &format!("http://127.0.0.1:{}", port.wrapping_add(1)),
    ] {
        let r = handshake(&local, Some(evil));
        assert!(r.starts_with("HTTP/1.1 403"), "Origin {evil}: {r}");
    }
    // DNS rebinding: a foreign name that resolves to this machine.
    for host in [
        format!("evil.example.com:{port}"),
        "evil.example.com".into(),
        format!("127.0.0.1:{}", port.wrapping_add(1)),
    ] {
        let r = handshake(&host, None);
        assert!(r.starts_with("HTTP/1.1 403"), "Host {host}: {r}");
        let r = raw(addr, &format!("GET / HTTP/1.1\r\nHost: {host}\r\n\r\n"));
        assert!(r.starts_with("HTTP/1.1 403"), "Host {host}: {r}");
        let r = raw(
            addr,
            &format!("GET /api/info HTTP/1.1\r\nHost: {host}\r\n\r\n"),
        );
        assert!(r.starts_with("HTTP/1.1 403"), "Host {host}: {r}");
    }
    let r = raw(addr, "GET / HTTP/1.1\r\n\r\n");
    assert!(r.starts_with("HTTP/1.1 403"), "no Host: {r}");
    // The viewer's own page, by address or as localhost.
    for own in [local.clone(), format!("localhost:{port}")] {
        let r = handshake(&own, Some(&format!("http://{own}")));
        assert!(r.starts_with("HTTP/1.1 101"), "{own}: {r}");
        let r = raw(addr, &format!("GET / HTTP/1.1\r\nHost: {own}\r\n\r\n"));
        assert!(r.starts_with("HTTP/1.1 200"), "{own}: {r}");
    }
}

#[test]
fn host_and_origin_rules() {
    let lo: SocketAddr = "127.0.0.1:8080".parse().expect("addr");
    let any: SocketAddr = "0.0.0.0:8080".parse().expect("addr");
    let lan: SocketAddr = "192.168.1.5:8080".parse().expect("addr");
    let v6: SocketAddr = "[::1]:8080".parse().expect("addr");
    let http: SocketAddr = "127.0.0.1:80".parse().expect("addr");
    assert!(host_allowed("127.0.0.1:8080", lo));
    assert!(host_allowed("LOCALHOST:8080", lo));
    assert!(host_allowed("[::1]:8080", lo), "loopback serves loopback");
    assert!(host_allowed("[::1]:8080", v6));
    assert!(host_allowed("localhost", http), "port 80 by default");
    assert!(!host_allowed("localhost", lo));
    assert!(!host_allowed("127.0.0.1:8081", lo));
    assert!(!host_allowed("evil.com:8080", lo));
    assert!(!host_allowed("127.0.0.1.evil.com:8080", lo));
    assert!(!host_allowed("[::1:8080", v6));
    assert!(!host_allowed("127.0.0.1:8080x", lo));
    assert!(!host_allowed("", lo));
    assert!(host_allowed("192.168.1.5:8080", lan));
    assert!(
        !host_allowed("localhost:8080", lan),
        "not served on loopback"
    );
    assert!(!host_allowed("10.0.0.1:8080", lan));
    assert!(
        host_allowed("10.0.0.1:8080", any),
        "any IP when serving all"
    );
    assert!(!host_allowed("myhost.lan:8080", any), "names are refused");
    assert!(origin_allowed(None, lo), "clients other than browsers");
    assert!(origin_allowed(Some("http://localhost:8080"), lo));
    assert!(!origin_allowed(Some("http://localhost:8080/x"), lo));
    assert!(!origin_allowed(Some("https://localhost:8080"), lo));
    assert!(!origin_allowed(Some("null"), lo));
    assert!(!origin_allowed(Some("http://evil.example.com"), lo));
}

#[test]
fn per_address_cap_sheds_waiting_connections_and_refuses_when_all_busy() {
    let (addr, handle) = start(ServeOptions {
        max_per_address: 4,
        ..ServeOptions::default()
    });
    let waiting: Vec<TcpStream> = (0..10)
        .map(|_| {
            let mut s = connect(addr);
            s.write_all(b"GET / HT").expect("write");
            s
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(handle.open_connections(), 4);
    let open: Vec<bool> = waiting
        .iter()
        .map(|s| !closed_by_server(s, Duration::from_millis(100)))
        .collect();
    assert_eq!(
        open,
        [
            false, false, false, false, false, false, true, true, true, true
        ],
        "the oldest waiting connections were shed"
    );
    // A normal request still gets through, shedding a waiting one.
    assert!(get(addr, "/").starts_with("HTTP/1.1 200"));
    drop(waiting);

    // When the address's only connection is busy rendering, a new one is
    // refused rather than shedding it.
    let (addr, _) = start(ServeOptions {
        max_per_address: 1,
        ..ServeOptions::default()
    });
    let mut busy = ws(addr);
    let long = json!({"type": "render", "id": 1, "width": 1024, "height": 1024,
        "progressive": true, "views": [{"technique": "path", "samples": 256}]});
    busy.send(Message::text(long.to_string())).expect("send");
    std::thread::sleep(Duration::from_millis(300));
    let r = get(addr, "/");
    assert!(r.starts_with("HTTP/1.1 503"), "{r}");
    drop(busy);
}

#[test]
fn an_idle_websocket_is_closed_after_the_idle_timeout() {
    let idle_timeout = Duration::from_millis(600);
    let (addr, handle) = start(ServeOptions {
        idle_timeout,
        ..ServeOptions::default()
    });
    // Activity resets the clock: a render at 400 ms keeps it open past 600.
    let mut c = ws(addr);
    let t = Instant::now();
    std::thread::sleep(Duration::from_millis(400));
    let m = json!({"type": "render", "id": 1, "width": 16, "height": 16,
        "views": [{"technique": "preview"}]});
    c.send(Message::text(m.to_string())).expect("send");
    let mut closed_at = None;
    for _ in 0..50 {
        match c.read() {
            Ok(Message::Close(frame)) => {
                let frame = frame.expect("a close frame with a reason");
                assert_eq!(u16::from(frame.code), 1001, "going away");
                closed_at = Some(t.elapsed());
                break;
            }
            Ok(_) => {}
            Err(e) => panic!("no close frame: {e}"),
        }
    }
    let closed_at = closed_at.expect("closed");
    assert!(
        closed_at > Duration::from_millis(950) && closed_at < Duration::from_secs(4),
        "closed after {closed_at:?}"
    );
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(handle.open_connections(), 0);
}

/// Issue 47: with two `Origin` or two `Host` headers, only the first was
/// checked. Each is refused now, whichever of the two is foreign, on the
/// page and on the WebSocket handshake.
#[test]
fn two_host_or_origin_headers_get_400() {
    let (addr, _handle) = start(ServeOptions::default());
    let own = format!("127.0.0.1:{}", addr.port());
    let ws = "Upgrade: websocket\r\nConnection: Upgrade\r\n\
              Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n";
    for (first, second) in [
        (own.as_str(), "evil.example.com"),
        ("evil.example.com", own.as_str()),
    ] {
        let r = raw_head(
            addr,
            &format!("GET / HTTP/1.1\r\nHost: {first}\r\nhost: {second}\r\n\r\n"),
        );
        assert!(r.starts_with("HTTP/1.1 400"), "{r}");
    }
    for (first, second) in [
        (
            format!("http://{own}"),
            "http://evil.example.com".to_string(),
        ),
        (
            "http://evil.example.com".to_string(),
            format!("http://{own}"),
        ),
    ] {
        let r = raw_head(
            addr,
            &format!(
                "GET /ws HTTP/1.1\r\nHost: {own}\r\nOrigin: {first}\r\nORIGIN: {second}\r\n{ws}\r\n"
            ),
        );
        assert!(r.starts_with("HTTP/1.1 400"), "{r}");
    }
    // One of each still opens.
    let r = raw_head(
        addr,
        &format!("GET /ws HTTP/1.1\r\nHost: {own}\r\nOrigin: http://{own}\r\n{ws}\r\n"),
    );
    assert!(r.starts_with("HTTP/1.1 101"), "{r}");
}
