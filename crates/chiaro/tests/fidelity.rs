//! The fidelity suite (ARCHITECTURE.md, "Fidelity suite"): every Khronos
//! sample model and asset-generator file, Mitsuba's Cornell box, the McGuire
//! OBJ scenes and the common test meshes in the shared assets are rendered
//! small with path, phong and flat and compared with their expected image
//! or screenshot (files without one: the path render) by the hue-palette
//! agreement described there. The expected
//! outcome of every (file, technique) is a row of `tests/data/fidelity.tsv`;
//! an outcome that differs from its row in either direction fails.
//!
//! `CHIARO_FIDELITY_TABLE=write` rewrites the table from this run (keeping
//! the hand-written reasons of rows whose outcome did not change);
//! `CHIARO_FIDELITY_SHEETS=DIR` writes contact sheets (path | phong | flat
//! | expected, one row a file) into DIR.

use chiaro::scene::{Camera, Technique};
use chiaro::{NoProgress, Scene, Vec3};
use chiaro_core::film::tonemap::to_srgb8;
use chiaro_core::framing::{UpAxis, frame_scene};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Image size of every render (square: the references are near square).
/// `CHIARO_FIDELITY_SIZE` changes it for looking at the sheets only: the
/// table's figures are for 96.
fn size() -> u32 {
    std::env::var("CHIARO_FIDELITY_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(96)
}
/// Path tracer samples per pixel: enough for the palette, not for noise-free
/// pictures.
const PATH_SPP: u32 = 8;
/// Samples per pixel of a path render that is the expected image of the
/// other techniques (files without a picture of their own).
const OWN_PATH_SPP: u32 = 32;
/// The palette agreement at or above which a render passes (see
/// ARCHITECTURE.md for why this value).
const PASS: f32 = 0.6;
/// The asset generator's viewer camera: Babylon.js's default vertical field
/// of view (0.8 rad); the position is in each folder's Manifest.json.
const GENERATOR_FOV_DEGREES: f32 = 45.836_624;

const TABLE: &str = "tests/data/fidelity.tsv";

/// What a file's renders are compared with.
#[derive(Debug, Clone, PartialEq)]
enum Compare {
    /// Nothing to compare with.
    Nothing,
    /// An author's screenshot: another camera, so palettes are compared as
    /// a whole.
    Screenshot(PathBuf),
    /// An expected image made with the camera we render with: compared cell
    /// by cell.
    SameCamera(PathBuf),
    /// No image of the author's (OBJ and PLY files): the path tracer's own
    /// render is the expected image of the other techniques, cell by cell.
    OwnPath,
}

/// One file of the suite.
struct Entry {
    /// Stable name: the path below the shared assets folder.
    id: String,
    path: PathBuf,
    compare: Compare,
    /// The generator's own camera position (looking at the origin, +y up);
    /// `None`: the file's camera or automatic framing.
    camera: Option<Vec3>,
    /// The file asks for a newer glTF than 2.0 (`asset.minVersion`): a 2.0
    /// reader must refuse it.
    must_refuse: Option<String>,
}

/// `asset.minVersion` of a .gltf file when it is above 2.0.
fn min_version_above_2_0(path: &Path) -> Option<String> {
    let text = std::fs::read_to_string(path).ok()?;
    let json: serde_json::Value = serde_json::from_str(&text).ok()?;
    let v = json["asset"]["minVersion"].as_str()?;
    (v != "2.0").then(|| v.to_string())
}

fn entries(root: &Path) -> Vec<Entry> {
    let mut v = Vec::new();
    let gen_root = root.join("khronos-gltf-asset-generator");
    for folder in sorted_dirs(&gen_root) {
        let Ok(text) = std::fs::read_to_string(folder.join("Manifest.json")) else {
            continue;
        };
        let manifest: serde_json::Value = serde_json::from_str(&text).expect("manifest is JSON");
        for m in manifest["models"].as_array().into_iter().flatten() {
            let file = m["fileName"].as_str().expect("fileName");
            let t = &m["camera"]["translation"];
            let camera = (0..3)
                .map(|i| t[i].as_f64().map(|x| x as f32))
                .collect::<Option<Vec<f32>>>()
                .map(|c| Vec3::new(c[0], c[1], c[2]));
            v.push(Entry {
                id: rel(root, &folder.join(file)),
                path: folder.join(file),
                compare: m["sampleImageName"]
                    .as_str()
                    .map_or(Compare::Nothing, |s| Compare::SameCamera(folder.join(s))),
                camera,
                must_refuse: min_version_above_2_0(&folder.join(file)),
            });
        }
    }
    for model in sorted_dirs(&root.join("khronos-gltf-sample-assets")) {
        let name = model.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if name.starts_with('_') {
            continue;
        }
        // GIF screenshots (animated models) are not decoded: no reference.
        let reference = sorted_files(&model.join("screenshot"))
            .into_iter()
            .find(|p| matches!(ext(p).as_str(), "png" | "jpg" | "jpeg"));
        for variant in sorted_dirs(&model) {
            for file in sorted_files(&variant) {
                if matches!(ext(&file).as_str(), "gltf" | "glb") {
                    v.push(Entry {
                        id: rel(root, &file),
                        path: file,
                        compare: reference
                            .clone()
                            .map_or(Compare::Nothing, Compare::Screenshot),
                        camera: None,
                        must_refuse: None,
                    });
                }
            }
        }
    }
    // Mitsuba's Cornell box, whose documentation render uses the scene's
    // own camera.
    let cbox = root.join("cornell-box");
    let xml = cbox.join("mitsuba3-cbox/cbox-rgb.xml");
    if xml.is_file() {
        v.push(Entry {
            id: rel(root, &xml),
            path: xml,
            compare: Compare::SameCamera(cbox.join("mitsuba3-docs-renders/variants_cbox_rgb.jpg")),
            camera: None,
            must_refuse: None,
        });
    }
    // OBJ and PLY scenes and meshes, which come with no picture.
    for folder in [
        "mcguire-archive/CornellBox",
        "mcguire-archive/LostEmpire",
        "common-3d-test-models",
    ] {
        for file in sorted_files(&root.join(folder)) {
            if matches!(ext(&file).as_str(), "obj" | "ply") && !is_obj_fragment(&file) {
                v.push(Entry {
                    id: rel(root, &file),
                    path: file,
                    compare: Compare::OwnPath,
                    camera: None,
                    must_refuse: None,
                });
            }
        }
    }
    v
}

/// An OBJ file that is a piece of another scene rather than a scene (the
/// McGuire archive's `water.obj` is the water surface of CornellBox-Water).
fn is_obj_fragment(p: &Path) -> bool {
    p.file_name().is_some_and(|n| n == "water.obj")
}

fn ext(p: &Path) -> String {
    p.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

fn rel(root: &Path, p: &Path) -> String {
    p.strip_prefix(root)
        .unwrap_or(p)
        .to_string_lossy()
        .replace('\\', "/")
}

/// The entries of folder `p` that `keep` accepts, sorted by path (none
/// where it cannot be read).
fn sorted_entries(p: &Path, keep: fn(&Path) -> bool) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(p)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| keep(p))
        .collect();
    v.sort();
    v
}

fn sorted_dirs(p: &Path) -> Vec<PathBuf> {
    sorted_entries(p, Path::is_dir)
}

fn sorted_files(p: &Path) -> Vec<PathBuf> {
    sorted_entries(p, Path::is_file)
}

// ------------------------------------------------------------ the measure

/// Number of palette classes: grey, 12 hue sectors, and black (nearly no
/// light: an unlit or missing surface, whatever its colour was meant to be).
const CLASSES: usize = 14;

/// Adds one sRGB pixel to a palette histogram: achromatic when dark or
/// unsaturated, else split linearly between the two nearest of 12 hue
/// sectors (30 degrees each), so a hue near a sector boundary does not flip.
fn add_pixel(h: &mut [f32; CLASSES], p: [u8; 3]) {
    let [r, g, b] = p.map(|c| c as f32 / 255.0);
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let chroma = max - min;
    if max < 0.04 {
        h[13] += 1.0;
        return;
    }
    if chroma < 0.2 * max {
        h[0] += 1.0;
        return;
    }
    let hue = if max == r {
        ((g - b) / chroma).rem_euclid(6.0)
    } else if max == g {
        (b - r) / chroma + 2.0
    } else {
        (r - g) / chroma + 4.0
    } * 2.0; // in sectors, 0..12
    let lo = hue.floor();
    let f = hue - lo;
    let lo = lo as usize % 12;
    h[1 + lo] += 1.0 - f;
    h[1 + (lo + 1) % 12] += f;
}

fn normalised(mut h: [f32; CLASSES]) -> [f32; CLASSES] {
    let s: f32 = h.iter().sum();
    if s > 0.0 {
        h.iter_mut().for_each(|x| *x /= s);
    }
    h
}

/// Histogram intersection of two normalised palettes, in [0, 1].
fn intersection(a: &[f32; CLASSES], b: &[f32; CLASSES]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x.min(*y)).sum()
}

/// The reference image box-filtered to `w` x `h` sRGB pixels, composited
/// over black where it has alpha.
fn reference_pixels(path: &Path, w: u32, h: u32) -> Result<Vec<[u8; 3]>, String> {
    let img = image::open(path)
        .map_err(|e| format!("{}: {e}", path.display()))?
        .to_rgba8();
    let (iw, ih) = img.dimensions();
    let mut out = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let (x0, x1) = (x * iw / w, ((x + 1) * iw / w).max(x * iw / w + 1));
            let (y0, y1) = (y * ih / h, ((y + 1) * ih / h).max(y * ih / h + 1));
            let mut acc = [0f32; 3];
            let mut n = 0f32;
            for yy in y0..y1.min(ih) {
                for xx in x0..x1.min(iw) {
                    let p = img.get_pixel(xx, yy).0;
                    let a = p[3] as f32 / 255.0;
                    for c in 0..3 {
                        acc[c] += p[c] as f32 * a;
                    }
                    n += 1.0;
                }
            }
            out.push(acc.map(|c| (c / n.max(1.0)).round() as u8));
        }
    }
    Ok(out)
}

/// Foreground of a screenshot: pixels that differ from the median of its
/// border (the viewer's plain background) by more than 10 % in a channel.
fn screenshot_foreground(px: &[[u8; 3]], w: usize, h: usize) -> Vec<bool> {
    let mut border: Vec<[u8; 3]> = Vec::new();
    for x in 0..w {
        border.push(px[x]);
        border.push(px[(h - 1) * w + x]);
    }
    for y in 0..h {
        border.push(px[y * w]);
        border.push(px[y * w + w - 1]);
    }
    let median = |c: usize| {
        let mut v: Vec<u8> = border.iter().map(|p| p[c]).collect();
        v.sort_unstable();
        v[v.len() / 2] as i32
    };
    let bg = [median(0), median(1), median(2)];
    px.iter()
        .map(|p| (0..3).any(|c| (p[c] as i32 - bg[c]).abs() > 25))
        .collect()
}

/// Hue names of the palette classes, for messages.
const CLASS_NAMES: [&str; CLASSES] = [
    "grey",
    "red",
    "orange",
    "yellow",
    "yellow-green",
    "green",
    "green-cyan",
    "cyan",
    "azure",
    "blue",
    "violet",
    "magenta",
    "rose",
    "black",
];

/// What the measure found on one render.
struct Measure {
    /// Palette agreement in [0, 1].
    agreement: f32,
    /// A hue that one image has and the other lacks, if any.
    presence: Option<String>,
}

/// Palette agreement of our render with the reference.
///
/// Own camera (the generator's files): the same pixels are compared, in a
/// 4 x 4 grid of cells over our foreground; the agreement is the mean of the
/// cells' palette intersections (cells under a quarter foreground skipped),
/// so a texture that is mirrored, mis-wrapped or missing lowers it.
/// Otherwise the framing differs: our foreground palette is compared with the
/// screenshot's foreground palette as a whole.
///
/// Either way a hue is checked for presence over the whole foreground: one
/// that covers 2 % of ours and under 0.4 % of the reference (a red error
/// marker, a wrong texture) or 5 % of the reference and under 1 % of ours (a
/// lost texture or vertex colour) fails however well the rest agrees.
fn measure(ours: &[[u8; 3]], fg: &[bool], reference: &[[u8; 3]], same_camera: bool) -> Measure {
    let n = size() as usize;
    let rfg = if same_camera {
        fg.to_vec()
    } else {
        screenshot_foreground(reference, n, n)
    };
    let (mut a, mut b) = ([0f32; CLASSES], [0f32; CLASSES]);
    for i in 0..n * n {
        if fg[i] {
            add_pixel(&mut a, ours[i]);
        }
        if rfg[i] {
            add_pixel(&mut b, reference[i]);
        }
    }
    if a.iter().sum::<f32>() == 0.0 || b.iter().sum::<f32>() == 0.0 {
        return Measure {
            agreement: 0.0,
            presence: Some("an empty foreground".into()),
        };
    }
    let (a, b) = (normalised(a), normalised(b));
    if std::env::var_os("CHIARO_FIDELITY_ONLY").is_some() {
        let show = |h: &[f32; CLASSES]| {
            (0..CLASSES)
                .filter(|&k| h[k] >= 0.005)
                .map(|k| format!("{} {:.1}", CLASS_NAMES[k], 100.0 * h[k]))
                .collect::<Vec<_>>()
                .join(", ")
        };
        eprintln!("  ours: {}\n  reference: {}", show(&a), show(&b));
    }
    let presence = (1..13).find_map(|k| {
        if a[k] >= 0.02 && b[k] < 0.004 {
            Some(format!(
                "{} in ours only ({:.1} %)",
                CLASS_NAMES[k],
                100.0 * a[k]
            ))
        } else if b[k] >= 0.05 && a[k] < 0.01 {
            Some(format!(
                "{} missing ({:.1} % of the reference)",
                CLASS_NAMES[k],
                100.0 * b[k]
            ))
        } else {
            None
        }
    });
    let agreement = if same_camera {
        const G: usize = 4;
        let mut total = 0.0;
        let mut cells = 0;
        for cy in 0..G {
            for cx in 0..G {
                let (mut a, mut b) = ([0f32; CLASSES], [0f32; CLASSES]);
                let mut count = 0;
                for y in cy * n / G..(cy + 1) * n / G {
                    for x in cx * n / G..(cx + 1) * n / G {
                        let i = y * n + x;
                        if fg[i] {
                            add_pixel(&mut a, ours[i]);
                            add_pixel(&mut b, reference[i]);
                            count += 1;
                        }
                    }
                }
                if count * 4 * G * G >= n * n {
                    total += intersection(&normalised(a), &normalised(b));
                    cells += 1;
                }
            }
        }
        if cells == 0 {
            0.0
        } else {
            total / cells as f32
        }
    } else {
        intersection(&a, &b)
    };
    Measure {
        agreement,
        presence,
    }
}

// ------------------------------------------------------------ running

#[derive(Debug, Clone, Copy, PartialEq)]
enum Outcome {
    Pass,
    KnownWrong,
    Unsupported,
    NoReference,
}

impl Outcome {
    fn name(self) -> &'static str {
        match self {
            Outcome::Pass => "pass",
            Outcome::KnownWrong => "known-wrong",
            Outcome::Unsupported => "unsupported",
            Outcome::NoReference => "no-reference",
        }
    }

    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "pass" => Outcome::Pass,
            "known-wrong" => Outcome::KnownWrong,
            "unsupported" => Outcome::Unsupported,
            "no-reference" => Outcome::NoReference,
            _ => return None,
        })
    }
}

struct Rendered {
    outcome: Outcome,
    score: Option<f32>,
    /// Why: the error of a refused file, the colour-presence finding.
    error: String,
    ours: Option<Vec<[u8; 3]>>,
}

fn load(e: &Entry) -> Result<Scene, String> {
    let mut scene = chiaro::io::load_scene(&e.path)
        .map_err(|err| err.to_string())?
        .scene;
    scene.render.width = size();
    scene.render.height = size();
    match e.camera {
        Some(eye) => {
            scene.camera = Camera {
                eye,
                look_at: Vec3::ZERO,
                up: Vec3::Y,
                fov_y_degrees: GENERATOR_FOV_DEGREES,
                ..scene.camera
            }
        }
        // Reframe for the square image unless the file chose its camera.
        None if scene.cameras.is_empty() && !matches!(e.compare, Compare::SameCamera(_)) => {
            scene.camera = frame_scene(&scene, UpAxis::Y, 1.0, None).camera;
        }
        None => {}
    }
    Ok(scene)
}

/// A render's sRGB pixels and its foreground (pixels that hit something).
struct Pixels {
    srgb: Vec<[u8; 3]>,
    fg: Vec<bool>,
}

/// Renders `e` with `tech`; `Err` is the outcome of a file that cannot be
/// rendered.
fn render(e: &Entry, scene: &Result<Scene, String>, tech: Technique) -> Result<Pixels, Rendered> {
    let scene = match scene {
        Ok(s) => s,
        Err(err) => return Err(Rendered::without_picture(Outcome::Unsupported, err.clone())),
    };
    if let Some(v) = &e.must_refuse {
        return Err(Rendered::without_picture(
            Outcome::KnownWrong,
            format!("loads, though it requires glTF {v} (asset.minVersion)"),
        ));
    }
    let mut s = scene.render.clone();
    s.technique = tech;
    s.samples = match tech {
        // The path render that the other techniques are judged by.
        Technique::Path if e.compare == Compare::OwnPath => OWN_PATH_SPP,
        Technique::Path => PATH_SPP,
        _ => 1,
    };
    s.path.max_depth = s.path.max_depth.min(6);
    let film = chiaro::render(scene, &s, &NoProgress)
        .map_err(|err| Rendered::without_picture(Outcome::Unsupported, err.to_string()))?;
    assert!(
        film.color.iter().all(|c| c.is_finite()),
        "{} ({}): a non-finite pixel",
        e.id,
        tech.name()
    );
    Ok(Pixels {
        srgb: to_srgb8(&film, s.tonemap, s.exposure),
        fg: film.depth.iter().map(|d| d.is_finite()).collect(),
    })
}

/// The outcome of a render against its expected image (`None`: there is
/// none).
fn judge(ours: Pixels, expected: Option<&[[u8; 3]]>, same_camera: bool) -> Rendered {
    let Some(reference) = expected else {
        return Rendered {
            outcome: Outcome::NoReference,
            score: None,
            error: String::new(),
            ours: Some(ours.srgb),
        };
    };
    let m = measure(&ours.srgb, &ours.fg, reference, same_camera);
    let sc = m.agreement;
    Rendered {
        outcome: if sc >= PASS && m.presence.is_none() {
            Outcome::Pass
        } else {
            Outcome::KnownWrong
        },
        score: Some(sc),
        error: m.presence.unwrap_or_default(),
        ours: Some(ours.srgb),
    }
}

impl Rendered {
    fn without_picture(outcome: Outcome, error: String) -> Self {
        Self {
            outcome,
            score: None,
            error,
            ours: None,
        }
    }
}

/// One expected row: outcome, recorded agreement and reason.
type Table = BTreeMap<(String, String), (Outcome, Option<f32>, String)>;

/// How far a known-wrong render's agreement may fall below its recorded
/// figure before it fails as a further regression.
const WORSE: f32 = 0.03;

fn read_table(path: &Path) -> Table {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let mut t = Table::new();
    for (n, line) in text.lines().enumerate() {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split('\t').collect();
        assert!(
            f.len() >= 4,
            "{TABLE}:{}: expected file, technique, outcome, score, reason",
            n + 1
        );
        let outcome = Outcome::parse(f[2])
            .unwrap_or_else(|| panic!("{TABLE}:{}: unknown outcome {:?}", n + 1, f[2]));
        t.insert(
            (f[0].to_string(), f[1].to_string()),
            (
                outcome,
                f[3].parse().ok(),
                f.get(4).unwrap_or(&"").to_string(),
            ),
        );
    }
    t
}

#[test]
fn shared_models_render_as_their_expected_images() {
    let Some(root) = chiaro_testkit::shared_assets() else {
        return;
    };
    let table_path = Path::new(env!("CARGO_MANIFEST_DIR")).join(TABLE);
    let expected = read_table(&table_path);
    let write = std::env::var("CHIARO_FIDELITY_TABLE").is_ok_and(|v| v == "write");
    let sheets = std::env::var_os("CHIARO_FIDELITY_SHEETS").map(PathBuf::from);
    // Path first: it is the expected image of files without one.
    let techs = [Technique::Path, Technique::Phong, Technique::Flat];

    let mut rows = String::from(
        "# Fidelity suite: expected outcome per file and technique (crates/chiaro/tests/fidelity.rs).\n\
         # file (below the shared assets, $CHIARO_ASSETS)\ttechnique\toutcome\tscore (palette agreement, pass >= 0.6)\treason\n",
    );
    let mut failures = Vec::new();
    let mut sheet_rows: Vec<SheetRow> = Vec::new();
    let started = std::time::Instant::now();
    // CHIARO_FIDELITY_ONLY=TEXT: only the files whose name contains TEXT
    // (for looking; the table is then not checked for the others).
    let only = std::env::var("CHIARO_FIDELITY_ONLY").unwrap_or_default();
    let all: Vec<Entry> = entries(&root)
        .into_iter()
        .filter(|e| e.id.contains(&only))
        .collect();
    for e in &all {
        let scene = load(e);
        let mut pics = Vec::new();
        let mut file_rows = Vec::new();
        let mut expected_image = match &e.compare {
            Compare::Screenshot(p) | Compare::SameCamera(p) => {
                Some(reference_pixels(p, size(), size()).expect("the reference image decodes"))
            }
            Compare::OwnPath | Compare::Nothing => None,
        };
        let same_camera = !matches!(e.compare, Compare::Screenshot(_));
        for &tech in &techs {
            let r = match render(e, &scene, tech) {
                Ok(ours) if tech == Technique::Path && e.compare == Compare::OwnPath => {
                    expected_image = Some(ours.srgb.clone());
                    judge(ours, None, same_camera)
                }
                Ok(ours) => judge(ours, expected_image.as_deref(), same_camera),
                Err(r) => r,
            };
            let key = (e.id.clone(), tech.name().to_string());
            let (want, recorded, reason) =
                expected
                    .get(&key)
                    .cloned()
                    .unwrap_or((Outcome::Pass, None, String::new()));
            let error = r
                .error
                .replace(&format!("{}/", root.display()), "")
                .replace(['\t', '\n'], " ");
            let figure = r.score.map_or("-".to_string(), |s| format!("{s:.3}"));
            if r.outcome != want || !expected.contains_key(&key) {
                failures.push(format!(
                    "{} ({}): {} (score {figure}{}), the table says {}{}: fix it, or if the change is \
                     right rerun with CHIARO_FIDELITY_TABLE=write",
                    e.id,
                    tech.name(),
                    r.outcome.name(),
                    if error.is_empty() { String::new() } else { format!(", {error}") },
                    if expected.contains_key(&key) { want.name() } else { "nothing" },
                    if reason.is_empty() { String::new() } else { format!(" ({reason})") },
                ));
            }
            if let (Outcome::KnownWrong, Some(then), Some(now)) = (r.outcome, recorded, r.score)
                && r.outcome == want
                && now < then - WORSE
            {
                failures.push(format!(
                    "{} ({}): known-wrong and worse: agreement {now:.3}, the table says {then:.3} ({reason})",
                    e.id,
                    tech.name()
                ));
            }
            // Hand-written reasons are kept while the outcome holds; refusals
            // and undiagnosed findings are refreshed from this run.
            let reason = if r.outcome == want
                && r.outcome == Outcome::KnownWrong
                && !reason.starts_with("not diagnosed yet")
            {
                reason
            } else if r.outcome == Outcome::Unsupported {
                error.clone()
            } else if r.outcome == Outcome::KnownWrong {
                format!("not diagnosed yet ({error})")
            } else {
                String::new()
            };
            file_rows.push((
                tech,
                format!(
                    "{}\t{}\t{}\t{figure}\t{reason}\n",
                    e.id,
                    tech.name(),
                    r.outcome.name()
                ),
            ));
            pics.push(r.ours);
        }
        // The table lists phong, path, flat (the order it had before flat).
        file_rows.sort_by_key(|(t, _)| {
            [Technique::Phong, Technique::Path, Technique::Flat]
                .iter()
                .position(|x| x == t)
        });
        rows.extend(file_rows.into_iter().map(|(_, line)| line));
        if sheets.is_some() {
            pics.push(expected_image);
            sheet_rows.push((e.id.clone(), pics));
        }
    }
    eprintln!(
        "fidelity: {} files x {} techniques in {:.1} s",
        all.len(),
        techs.len(),
        started.elapsed().as_secs_f32()
    );
    if let Some(dir) = sheets {
        write_sheets(&dir, &sheet_rows);
    }
    if only.is_empty() {
        let ran: std::collections::BTreeSet<&str> = all.iter().map(|e| e.id.as_str()).collect();
        for (file, tech) in expected.keys() {
            if !ran.contains(file.as_str()) {
                failures.push(format!("{file} ({tech}): in {TABLE} but not found"));
            }
        }
    }
    if write {
        assert!(
            only.is_empty(),
            "CHIARO_FIDELITY_TABLE=write runs every file: unset CHIARO_FIDELITY_ONLY"
        );
        std::fs::write(&table_path, rows).expect("writes the table");
        eprintln!("fidelity: wrote {}", table_path.display());
        return;
    }
    assert!(
        failures.is_empty(),
        "{} outcome(s) differ from {TABLE}:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// One row of a contact sheet: the file and its pictures (path, phong,
/// flat, expected), `None` where there is none.
type SheetRow = (String, Vec<Option<Vec<[u8; 3]>>>);

/// Contact sheets of 12 files each: path | phong | flat | expected per row, grey
/// where a picture is missing; the index of each row's file goes to
/// `sheets.txt` beside them.
fn write_sheets(dir: &Path, rows: &[SheetRow]) {
    std::fs::create_dir_all(dir).expect("creates the sheet folder");
    let s = size();
    let gap = 2;
    let mut index = String::new();
    for (page, chunk) in rows.chunks(12).enumerate() {
        let columns = chunk.iter().map(|r| r.1.len()).max().unwrap_or(0) as u32;
        let w = columns * s + (columns + 1) * gap;
        let h = chunk.len() as u32 * (s + gap) + gap;
        let mut img = image::RgbImage::from_pixel(w, h, image::Rgb([40, 40, 40]));
        for (r, (id, pics)) in chunk.iter().enumerate() {
            let _ = writeln!(index, "sheet-{page:02}.png row {r}: {id}");
            for (c, pic) in pics.iter().enumerate() {
                let (x0, y0) = (gap + c as u32 * (s + gap), gap + r as u32 * (s + gap));
                for y in 0..s {
                    for x in 0..s {
                        let p = pic
                            .as_ref()
                            .map_or([128, 128, 128], |p| p[(y * s + x) as usize]);
                        img.put_pixel(x0 + x, y0 + y, image::Rgb(p));
                    }
                }
            }
        }
        img.save(dir.join(format!("sheet-{page:02}.png")))
            .expect("writes a sheet");
    }
    std::fs::write(dir.join("sheets.txt"), index).expect("writes the index");
    eprintln!("fidelity: contact sheets in {}", dir.display());
}

#[test]
fn the_palette_measure_separates_hues_and_ignores_brightness() {
    let mut red = [0f32; CLASSES];
    let mut dark_red = [0f32; CLASSES];
    let mut grey = [0f32; CLASSES];
    add_pixel(&mut red, [220, 30, 20]);
    add_pixel(&mut dark_red, [90, 12, 8]);
    add_pixel(&mut grey, [128, 128, 128]);
    let (red, dark_red, grey) = (normalised(red), normalised(dark_red), normalised(grey));
    assert!(intersection(&red, &dark_red) > 0.95);
    assert!(intersection(&red, &grey) < 0.01);
    let mut green = [0f32; CLASSES];
    add_pixel(&mut green, [30, 200, 40]);
    assert!(intersection(&red, &normalised(green)) < 0.01);
}
