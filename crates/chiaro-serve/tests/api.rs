//! The HTTP and WebSocket API of `chiaro serve`: routes, bad requests,
//! absurd sizes, oversized messages, disconnects in the middle of a render,
//! the split view and saving.

use chiaro_serve::{ServeOptions, Server, parse_host};
use serde_json::{Value, json};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::time::Duration;
use tungstenite::{Message, WebSocket};

fn cornell() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.toml")
}

/// Starts a server for the Cornell box on a free loopback port.
fn start() -> SocketAddr {
    let opts = ServeOptions {
        port: 0,
        ..ServeOptions::default()
    };
    Server::bind(&cornell(), &opts)
        .expect("binds")
        .spawn()
        .expect("addr")
}

/// Sends raw bytes and returns the whole response.
fn raw(addr: SocketAddr, request: &[u8]) -> String {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(30)))
        .expect("timeout");
    s.write_all(request).expect("write");
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    String::from_utf8_lossy(&out).into_owned()
}

fn get(addr: SocketAddr, path: &str) -> String {
    raw(
        addr,
        format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\n\r\n").as_bytes(),
    )
}

type Ws = WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>;

fn ws(addr: SocketAddr) -> Ws {
    let (ws, _) = tungstenite::connect(format!("ws://{addr}/ws")).expect("websocket");
    ws
}

/// A received message: JSON text, or a binary frame's header and payload.
enum Got {
    Text(Value),
    Frame(Value, Vec<u8>),
    Closed,
}

fn next(ws: &mut Ws) -> Got {
    loop {
        match ws.read() {
            Ok(Message::Text(t)) => {
                return Got::Text(serde_json::from_str(t.as_str()).expect("JSON"));
            }
            Ok(Message::Binary(b)) => {
                let n = u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize;
                let h: Value = serde_json::from_slice(&b[4..4 + n]).expect("header JSON");
                return Got::Frame(h, b[4 + n..].to_vec());
            }
            Ok(Message::Close(_)) | Err(_) => return Got::Closed,
            Ok(_) => {}
        }
    }
}

fn send(ws: &mut Ws, v: Value) {
    ws.send(Message::text(v.to_string())).expect("send");
}

/// Reads until a text message of `kind` (returning it and the frames seen).
fn until(ws: &mut Ws, kind: &str) -> (Value, Vec<(Value, Vec<u8>)>) {
    let mut frames = Vec::new();
    loop {
        match next(ws) {
            Got::Text(v) if v["type"] == kind => return (v, frames),
            Got::Text(v) if v["type"] == "error" => panic!("unexpected error {v}"),
            Got::Text(_) => {}
            Got::Frame(h, p) => frames.push((h, p)),
            Got::Closed => panic!("closed while waiting for {kind}"),
        }
    }
}

/// A render far longer than any test: path tracing at the page limits.
fn long_render(id: u64) -> Value {
    json!({"type": "render", "id": id, "width": 1024, "height": 1024,
           "progressive": true, "views": [{"technique": "path", "samples": 256}]})
}

fn small_render(id: u64, technique: &str) -> Value {
    json!({"type": "render", "id": id, "width": 32, "height": 32, "progressive": true,
           "views": [{"technique": technique}]})
}

const PNG_MAGIC: &[u8] = b"\x89PNG\r\n\x1a\n";

#[test]
fn http_routes_and_bad_requests() {
    let addr = start();
    let page = get(addr, "/");
    assert!(page.starts_with("HTTP/1.1 200"), "{page}");
    assert!(page.contains("<canvas") && page.contains("/app.js"));
    assert!(get(addr, "/app.js").contains("new WebSocket"));
    assert!(get(addr, "/style.css").starts_with("HTTP/1.1 200"));
    let info = get(addr, "/api/info");
    let body = info.split("\r\n\r\n").nth(1).expect("body");
    let v: Value = serde_json::from_str(body).expect("JSON");
    assert_eq!(v["scene"], "cornell-box");
    assert!(
        v["techniques"]
            .as_array()
            .expect("list")
            .iter()
            .any(|t| t == "whitted")
    );
    assert!(get(addr, "/../../etc/passwd").starts_with("HTTP/1.1 404"));
    assert!(get(addr, "/scenes/cornell-box.toml").starts_with("HTTP/1.1 404"));
    let post = format!("POST / HTTP/1.1\r\nHost: {addr}\r\nContent-Length: 0\r\n\r\n");
    assert!(raw(addr, post.as_bytes()).starts_with("HTTP/1.1 405"));
    assert!(raw(addr, b"\x00\x01 garbage \xff\r\n\r\n").starts_with("HTTP/1.1 400"));
    let huge = format!(
        "GET / HTTP/1.1\r\nHost: {addr}\r\nX: {}\r\n\r\n",
        "a".repeat(40_000)
    );
    assert!(raw(addr, huge.as_bytes()).starts_with("HTTP/1.1 431"));
    assert!(
        get(addr, "/ws").starts_with("HTTP/1.1 400"),
        "no upgrade headers"
    );
    // A client that connects and says nothing, or closes half-way, is harmless.
    drop(TcpStream::connect(addr).expect("connect"));
    let mut half = TcpStream::connect(addr).expect("connect");
    half.write_all(b"GET / HTT").expect("write");
    drop(half);
    assert!(get(addr, "/").starts_with("HTTP/1.1 200"), "still serving");
}

#[test]
fn renders_bands_and_answers_done() {
    let addr = start();
    let mut c = ws(addr);
    send(&mut c, small_render(7, "preview"));
    let (done, frames) = until(&mut c, "done");
    assert_eq!(done["id"], 7);
    assert_eq!(done["technique"], "preview");
    assert!(frames.len() >= 2, "progressive bands ({})", frames.len());
    let rows: u64 = frames
        .iter()
        .map(|(h, _)| h["h"].as_u64().expect("h"))
        .sum();
    assert_eq!(rows, 32, "bands cover the image once");
    for (h, png) in &frames {
        assert_eq!(h["kind"], "tile");
        assert!(png.starts_with(PNG_MAGIC));
    }
    // Whole-frame (non-progressive) renders send one tile.
    send(
        &mut c,
        json!({"type": "render", "id": 8, "width": 16, "height": 12,
        "views": [{"technique": "phong", "shadows": "map", "model": "blinn"}]}),
    );
    let (done, frames) = until(&mut c, "done");
    assert_eq!((done["id"].as_u64(), frames.len()), (Some(8), 1));
    assert_eq!(
        (frames[0].0["w"].as_u64(), frames[0].0["h"].as_u64()),
        (Some(16), Some(12))
    );
}

#[test]
fn bad_json_and_absurd_requests_get_errors_and_the_connection_survives() {
    let addr = start();
    let mut c = ws(addr);
    let bad = [
        Value::String("{not json".into()),
        json!({"type": "explode"}),
        json!({"type": "render", "id": 1, "width": 100000, "height": 100000, "views": [{}]}),
        json!({"type": "render", "id": 1, "width": 32, "height": 32, "views": [{"samples": 1_000_000_000}]}),
        json!({"type": "render", "id": 1, "views": [{"technique": "raytrace-everything"}]}),
        json!({"type": "render", "id": 1, "views": []}),
        json!({"type": "render", "id": 1, "views": [{}, {}, {}]}),
        json!({"type": "render", "id": 1, "views": [{"shadows": "/etc/passwd"}]}),
        json!({"type": "render", "id": 1, "orbit": {"zoom": 0}, "views": [{}]}),
        json!({"type": "render", "id": 1, "width": -5, "views": [{}]}),
        json!({"type": "render", "id": 1, "views": [{"scene": "/etc/passwd"}]}),
        json!({"type": "save", "view": 0, "format": "png"}),
        json!({"type": "save", "view": 99, "format": "png"}),
    ];
    for b in bad {
        let text = match &b {
            Value::String(s) => s.clone(),
            v => v.to_string(),
        };
        c.send(Message::text(text)).expect("send");
        match next(&mut c) {
            Got::Text(v) => assert_eq!(v["type"], "error", "{b} -> {v}"),
            _ => panic!("{b}: expected an error message"),
        }
    }
    c.send(Message::binary(vec![1u8, 2, 3])).expect("send");
    assert!(matches!(next(&mut c), Got::Text(v) if v["type"] == "error"));
    send(&mut c, small_render(2, "phong"));
    let (done, _) = until(&mut c, "done");
    assert_eq!(done["id"], 2);
}

#[test]
fn oversized_message_closes_only_that_connection() {
    let addr = start();
    let mut c = ws(addr);
    let big = format!(
        "{{\"type\":\"render\",\"pad\":\"{}\"}}",
        "x".repeat(200_000)
    );
    let _ = c.send(Message::text(big));
    let mut closed = false;
    for _ in 0..4 {
        match next(&mut c) {
            Got::Closed => {
                closed = true;
                break;
            }
            Got::Text(v) => assert_eq!(v["type"], "error"),
            Got::Frame(..) => panic!("no frames expected"),
        }
    }
    assert!(
        closed,
        "the server drops a connection that sends oversized messages"
    );
    let mut d = ws(addr);
    send(&mut d, small_render(1, "preview"));
    assert_eq!(until(&mut d, "done").0["id"], 1);
}

#[test]
fn closing_the_tab_mid_render_cancels_it_and_the_server_goes_on() {
    let addr = start();
    for _ in 0..3 {
        let mut c = ws(addr);
        // A render far longer than the test: path tracing at the page limits.
        send(&mut c, long_render(1));
        std::thread::sleep(Duration::from_millis(50));
        drop(c);
    }
    // A raw TCP close right after the upgrade, without a close frame.
    let mut s = TcpStream::connect(addr).expect("connect");
    let handshake = format!(
        "GET /ws HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    );
    s.write_all(handshake.as_bytes()).expect("write");
    let mut buf = [0u8; 256];
    let n = s.read(&mut buf).expect("read");
    let reply = String::from_utf8_lossy(&buf[..n]);
    assert!(reply.starts_with("HTTP/1.1 101"), "{reply}");
    assert!(
        reply.contains("s3pPLMBiTxaQ9kYGzzhZRbK+xOo="),
        "RFC 6455 example accept key: {reply}"
    );
    drop(s);
    // The cancelled renders give the CPU back: a new page renders.
    let mut c = ws(addr);
    send(&mut c, small_render(5, "whitted"));
    assert_eq!(until(&mut c, "done").0["id"], 5);
}

#[test]
fn a_newer_request_supersedes_the_running_one() {
    let addr = start();
    let mut c = ws(addr);
    send(&mut c, long_render(1));
    send(&mut c, small_render(2, "preview"));
    let (done, _) = until(&mut c, "done");
    assert_eq!(
        done["id"], 2,
        "the long render was cancelled, not finished first"
    );
}

#[test]
fn split_view_sends_difference_and_metrics_and_saves() {
    let addr = start();
    let mut c = ws(addr);
    send(
        &mut c,
        json!({"type": "render", "id": 3, "width": 24, "height": 24,
        "views": [{"technique": "phong"}, {"technique": "path", "samples": 4}]}),
    );
    let (m, frames) = until(&mut c, "metrics");
    assert_eq!(m["id"], 3);
    // The numbers `chiaro compare` reports, ranked by relMSE and FLIP.
    let rel = m["relative_mse"].as_f64().expect("relative_mse");
    let flip = m["flip"].as_f64().expect("flip");
    assert!(rel > 0.0 && rel.is_finite(), "{rel}");
    assert!(flip > 0.0 && flip < 1.0, "{flip}");
    let psnr = m["display_psnr"]
        .as_f64()
        .expect("finite display PSNR between different techniques");
    assert!(psnr > 5.0 && psnr < 60.0, "{psnr}");
    for key in ["rmse", "psnr", "mean_relative_error"] {
        assert!(m[key].as_f64().expect(key) > 0.0, "{key}: {}", m[key]);
    }
    assert!(
        frames
            .iter()
            .any(|(h, p)| h["kind"] == "diff" && p.starts_with(PNG_MAGIC))
    );
    assert!(
        frames
            .iter()
            .any(|(h, _)| h["view"] == 1 && h["kind"] == "tile")
    );
    send(&mut c, json!({"type": "save", "view": 1, "format": "exr"}));
    match next(&mut c) {
        Got::Frame(h, bytes) => {
            assert_eq!(h["kind"], "file");
            assert_eq!(h["name"], "cornell-box-path.exr");
            assert_eq!(&bytes[..4], &[0x76, 0x2f, 0x31, 0x01], "EXR magic");
        }
        _ => panic!("expected a file"),
    }
    send(&mut c, json!({"type": "save", "view": 0, "format": "png"}));
    match next(&mut c) {
        Got::Frame(h, bytes) => {
            assert_eq!(h["name"], "cornell-box-phong.png");
            assert!(bytes.starts_with(PNG_MAGIC));
        }
        _ => panic!("expected a file"),
    }
    send(
        &mut c,
        json!({"type": "save", "view": 0, "format": "../../x"}),
    );
    assert!(matches!(next(&mut c), Got::Text(v) if v["type"] == "error"));
}

#[test]
fn identical_views_measure_no_error_and_an_infinite_psnr_as_null() {
    let addr = start();
    let mut c = ws(addr);
    send(
        &mut c,
        json!({"type": "render", "id": 4, "width": 16, "height": 16,
        "views": [{"technique": "phong"}, {"technique": "phong"}]}),
    );
    let (m, _) = until(&mut c, "metrics");
    assert_eq!(m["relative_mse"].as_f64(), Some(0.0), "{m}");
    assert!(m["flip"].as_f64().expect("flip") < 1e-6, "{m}");
    assert!(m["display_psnr"].is_null() && m["psnr"].is_null(), "{m}");
}

#[test]
fn refine_sends_a_quick_full_size_pass_then_full_quality() {
    let addr = start();
    let mut c = ws(addr);
    send(
        &mut c,
        json!({"type": "render", "id": 4, "width": 24, "height": 16, "refine": true,
            "progressive": true, "views": [{"technique": "phong", "samples": 2}]}),
    );
    let mut passes = Vec::new();
    let mut frames_per_pass = Vec::new();
    let done = loop {
        match next(&mut c) {
            Got::Text(v) if v["type"] == "pass" => {
                assert_eq!(v["id"], 4);
                passes.push((v["pass"].as_u64(), v["of"].as_u64()));
                frames_per_pass.push(0);
            }
            Got::Text(v) if v["type"] == "done" => break v,
            Got::Text(v) if v["type"] == "error" => panic!("{v}"),
            Got::Text(_) => {}
            Got::Frame(h, png) => {
                assert_eq!(
                    (h["width"].as_u64(), h["height"].as_u64()),
                    (Some(24), Some(16))
                );
                assert!(png.starts_with(PNG_MAGIC));
                *frames_per_pass.last_mut().expect("a pass before frames") += 1;
            }
            Got::Closed => panic!("closed"),
        }
    };
    assert_eq!(passes, [(Some(1), Some(2)), (Some(2), Some(2))]);
    assert!(
        frames_per_pass.iter().all(|&n| n >= 1),
        "{frames_per_pass:?}"
    );
    assert_eq!(
        (done["samples"].as_u64(), done["light_samples"].as_u64()),
        (Some(2), Some(16))
    );
    // Already as cheap as a draft: one pass, no announcement.
    send(
        &mut c,
        json!({"type": "render", "id": 5, "width": 8, "height": 8, "refine": true,
            "views": [{"technique": "phong", "samples": 1, "light_samples": 1}]}),
    );
    let (done, frames) = until(&mut c, "done");
    assert_eq!((done["id"].as_u64(), frames.len()), (Some(5), 1));
}

#[test]
fn orbiting_a_radiosity_render_reuses_the_solution() {
    // Coarse patches and analytic form factors keep each solve short.
    let mut scene = chiaro::io::load_scene(&cornell()).expect("scene").scene;
    scene.render.radiosity.patch_size = 150.0;
    scene.render.radiosity.solver = chiaro::scene::RadiositySolver::Jacobi;
    scene.render.radiosity.formfactor = chiaro::scene::FormFactorMethod::Analytic;
    let opts = ServeOptions {
        port: 0,
        ..ServeOptions::default()
    };
    let addr = Server::bind_scene(scene, "coarse-box", &opts)
        .expect("binds")
        .spawn()
        .expect("addr");
    let mut c = ws(addr);
    let render = |id: u64, yaw: f32, model: &str| {
        json!({"type": "render", "id": id, "width": 16, "height": 16,
            "orbit": {"yaw": yaw}, "views": [{"technique": "radiosity", "model": model}]})
    };
    send(&mut c, render(1, 0.0, "scene"));
    let (a, fa) = until(&mut c, "done");
    send(&mut c, render(2, 0.3, "scene"));
    let (b, fb) = until(&mut c, "done");
    assert_eq!(
        (
            a["radiosity_solves"].as_u64(),
            b["radiosity_solves"].as_u64()
        ),
        (Some(1), Some(1))
    );
    assert_ne!(fa[0].1, fb[0].1, "the camera moved");
    // Hybrid shares it; another illumination model changes the materials.
    send(
        &mut c,
        json!({"type": "render", "id": 3, "width": 16, "height": 16,
            "views": [{"technique": "hybrid"}]}),
    );
    assert_eq!(until(&mut c, "done").0["radiosity_solves"], 1);
    send(&mut c, render(4, 0.0, "blinn"));
    assert_eq!(until(&mut c, "done").0["radiosity_solves"], 2);
}

#[test]
fn hosts_are_ip_addresses_and_loopback_by_default() {
    assert!(
        parse_host(&ServeOptions::default().host)
            .expect("valid")
            .is_loopback()
    );
    assert!(parse_host("localhost").expect("valid").is_loopback());
    assert!(parse_host("0.0.0.0").is_ok(), "asked for explicitly");
    assert!(parse_host("example.com").is_err());
    assert!(parse_host("").is_err());
    let taken = start();
    let opts = ServeOptions {
        port: taken.port(),
        ..ServeOptions::default()
    };
    assert!(Server::bind(&cornell(), &opts).is_err(), "port in use");
    let missing = ServeOptions {
        port: 0,
        ..ServeOptions::default()
    };
    assert!(Server::bind(&cornell().with_file_name("no-such.toml"), &missing).is_err());
}
