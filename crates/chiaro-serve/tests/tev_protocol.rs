//! The tev packets chiaro sends, against tev's own Python client.
//!
//! `fixtures/tev_create.bin` and `fixtures/tev_update.bin` were written by
//! `fixtures/gen_tev_fixtures.py` with `tevclient` 1.0.4 from PyPI
//! (`.ci/web.sh` regenerates them and compares).

use chiaro::scene::{Geometry, Material, Object, Scene, Technique};
use chiaro::{NoProgress, Vec3};
use chiaro_serve::tev::{self, RGB};
use std::io::Read;
use std::net::TcpListener;

const CREATE: &[u8] = include_bytes!("fixtures/tev_create.bin");
const UPDATE: &[u8] = include_bytes!("fixtures/tev_update.bin");

#[test]
fn create_packet_matches_tevclient() {
    let ours = tev::create_image_packet("chiaro-test", 5, 4, &RGB, true).expect("encodes");
    assert_eq!(ours, CREATE);
}

#[test]
fn update_packet_matches_tevclient() {
    // The same 3x2 tile as the script: value (row * 9 + col * 3 + c) / 256.
    let data: Vec<f32> = (0..18).map(|k| k as f32 / 256.0).collect();
    let ours =
        tev::update_image_packet("chiaro-test", &RGB, 1, 2, 3, 2, &data, false).expect("encodes");
    assert_eq!(ours.len(), UPDATE.len());
    assert_eq!(ours, UPDATE);
}

/// Splits a byte stream into tev packets by their length prefix.
fn packets(mut bytes: &[u8]) -> Vec<&[u8]> {
    let mut out = Vec::new();
    while bytes.len() >= 4 {
        let n = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as usize;
        assert!(n >= 5 && n <= bytes.len(), "bad packet length {n}");
        out.push(&bytes[..n]);
        bytes = &bytes[n..];
    }
    assert!(bytes.is_empty());
    out
}

fn read_i32(b: &[u8], at: &mut usize) -> i32 {
    let v = i32::from_le_bytes([b[*at], b[*at + 1], b[*at + 2], b[*at + 3]]);
    *at += 4;
    v
}

fn skip_str(b: &[u8], at: &mut usize) -> String {
    let end = b[*at..].iter().position(|&c| c == 0).expect("NUL") + *at;
    let s = String::from_utf8(b[*at..end].to_vec()).expect("utf8");
    *at = end + 1;
    s
}

#[test]
fn render_to_tev_streams_the_whole_image() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = listener.local_addr().expect("addr").to_string();
    let reader = std::thread::spawn(move || {
        let (mut s, _) = listener.accept().expect("accept");
        let mut all = Vec::new();
        s.read_to_end(&mut all).expect("read");
        all
    });
    let mut scene = Scene::default();
    scene.add_material(Material::diffuse("white", Vec3::splat(0.8)));
    scene.objects.push(Object {
        geometry: Geometry::Sphere { radius: 1.0 },
        ..Default::default()
    });
    let mut settings = scene.render.clone();
    settings.technique = Technique::Preview;
    settings.width = 24;
    settings.height = 20;
    let (film, _) = tev::render_to_tev(&scene, &settings, &NoProgress, &addr, "t").expect("render");
    let whole = chiaro::render(&scene, &settings, &NoProgress).expect("render");
    assert_eq!(film, whole, "banded render equals a whole render");
    let bytes = reader.join().expect("reader");
    let ps = packets(&bytes);
    assert_eq!(ps[0][4], 4, "create first");
    let mut got = vec![f32::NAN; 24 * 20 * 3];
    let mut updates = 0;
    for p in &ps[1..] {
        assert_eq!(p[4], 6, "then updates");
        updates += 1;
        let mut at = 6;
        assert_eq!(skip_str(p, &mut at), "t");
        assert_eq!(read_i32(p, &mut at), 3);
        for c in ["R", "G", "B"] {
            assert_eq!(skip_str(p, &mut at), c);
        }
        let (x, y, w, h) = (
            read_i32(p, &mut at),
            read_i32(p, &mut at),
            read_i32(p, &mut at),
            read_i32(p, &mut at),
        );
        assert_eq!((x, w), (0, 24));
        at += 6 * 8;
        for row in 0..h {
            for col in 0..w {
                for c in 0..3 {
                    let k = at + (((row * w + col) * 3 + c) * 4) as usize;
                    let v = f32::from_le_bytes([p[k], p[k + 1], p[k + 2], p[k + 3]]);
                    got[(((y + row) * 24 + col) * 3 + c) as usize] = v;
                }
            }
        }
    }
    assert!(updates >= 2, "the preview is sent in bands ({updates})");
    for (i, c) in whole.color.iter().enumerate() {
        assert_eq!(
            [got[i * 3], got[i * 3 + 1], got[i * 3 + 2]],
            [c.x, c.y, c.z],
            "pixel {i}"
        );
    }
}

#[test]
fn connect_to_nothing_is_an_error() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = listener.local_addr().expect("addr").to_string();
    drop(listener);
    assert!(matches!(
        tev::TevClient::connect(&addr),
        Err(tev::TevError::Connect { .. })
    ));
}
