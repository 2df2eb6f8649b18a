//! Regenerates `assets/studio_small_03_256x128.hdr` (the benchmarks'
//! studio environment) from Poly Haven's CC0 `studio_small_03_1k.hdr`: a box
//! filter over whole source texels down to `W H` (16x8 when not given;
//! the shipped map is made with `256 128`).
//!
//! `cargo run -p chiaro-io --example downsample_hdr -- IN.hdr OUT.hdr [W H]`

use image::Rgb;
use image::codecs::hdr::HdrEncoder;
use std::fs::File;
use std::io::BufWriter;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (input, output, w, h) = match args.as_slice() {
        [_, i, o] => (i, o, 16u32, 8u32),
        [_, i, o, w, h] => (i, o, w.parse()?, h.parse()?),
        _ => return Err("usage: downsample_hdr IN.hdr OUT.hdr [W H]".into()),
    };
    let src = image::open(input)?.to_rgb32f();
    let (fx, fy) = (src.width() / w.max(1), src.height() / h.max(1));
    if fx == 0 || fy == 0 {
        return Err(format!("the input is smaller than {w}x{h}").into());
    }
    let mut out = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let mut sum = [0f32; 3];
            for j in 0..fy {
                for i in 0..fx {
                    let p = src.get_pixel(x * fx + i, y * fy + j);
                    for c in 0..3 {
                        sum[c] += p[c];
                    }
                }
            }
            let n = (fx * fy) as f32;
            out.push(Rgb([sum[0] / n, sum[1] / n, sum[2] / n]));
        }
    }
    HdrEncoder::new(BufWriter::new(File::create(output)?)).encode(&out, w as usize, h as usize)?;
    Ok(())
}
