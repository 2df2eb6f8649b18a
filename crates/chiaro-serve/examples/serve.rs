//! `cargo run -p chiaro-serve --example serve -- SCENE [--port P] [--host H]`:
//! what `chiaro serve` does, for testing before the CLI wires it.

use chiaro_serve::{ServeOptions, serve};
use std::path::PathBuf;

fn main() {
    let mut args = std::env::args().skip(1);
    let mut scene = None;
    let mut opts = ServeOptions::default();
    while let Some(a) = args.next() {
        match a.as_str() {
            "--port" => match args.next().and_then(|p| p.parse().ok()) {
                Some(p) => opts.port = p,
                None => fail("--port needs a number from 0 to 65535"),
            },
            "--host" => match args.next() {
                Some(h) => opts.host = h,
                None => fail("--host needs an IP address"),
            },
            _ if scene.is_none() => scene = Some(PathBuf::from(a)),
            other => fail(&format!("unexpected argument `{other}`")),
        }
    }
    let Some(scene) = scene else {
        fail("usage: serve SCENE [--port P] [--host H]")
    };
    if let Err(e) = serve(&scene, opts) {
        fail(&e.to_string());
    }
}

fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(2)
}
