//! A directive's parameter list: `"type name" value` or `"type name" [
//! values ]`, read with typed getters that remember what was read, so the
//! rest can be reported as ignored (pbrt's "unused parameter").

use super::lexer::{Kind, Lexer, Loc, Token, number_of};
use crate::Result;
use chiaro_core::{Vec2, Vec3};
use std::cell::Cell;

/// The values of one parameter, by the kind its type declares.
#[derive(Debug, Clone, PartialEq)]
pub enum Values {
    /// Numbers (`float`, `integer`, points, vectors, normals, `rgb`,
    /// `blackbody`, a `spectrum` of wavelength/value pairs).
    Numbers(Vec<f32>),
    /// Strings (`string`, `texture`, a named `spectrum`).
    Strings(Vec<String>),
    /// Booleans.
    Bools(Vec<bool>),
}

/// One parameter.
#[derive(Debug, Clone)]
pub struct Param {
    /// The declared type (`color` read as `rgb`, `point` as `point3`, ...).
    pub ty: String,
    /// The name.
    pub name: String,
    /// The values.
    pub values: Values,
    /// Where its declaration starts.
    pub loc: Loc,
    used: Cell<bool>,
}

/// The parameter types pbrt-v4 and pbrt-v3 declare.
const TYPES: &[&str] = &[
    "float",
    "integer",
    "bool",
    "string",
    "texture",
    "point",
    "point2",
    "point3",
    "vector",
    "vector2",
    "vector3",
    "normal",
    "normal3",
    "rgb",
    "color",
    "spectrum",
    "blackbody",
];

/// A spectrum-valued parameter as written.
#[derive(Debug, Clone, PartialEq)]
pub enum Spectrum {
    /// `rgb` / `color`, or a `float` (grey).
    Rgb(Vec3),
    /// `blackbody T` (pbrt-v4), or `blackbody [T scale]` (pbrt-v3).
    Blackbody(f32, f32),
    /// A named spectrum (`"metal-Cu-eta"`, `"glass-BK7"`, `"stdillum-D65"`).
    Named(String),
    /// Wavelength/value pairs.
    Pairs(Vec<(f32, f32)>),
    /// A `texture` parameter: the texture's name.
    Texture(String),
}

/// A directive's parameters.
#[derive(Debug, Clone, Default)]
pub struct Params {
    /// In file order.
    pub list: Vec<Param>,
}

impl Params {
    /// Reads parameters while the next token is a quoted string.
    pub fn read(lx: &mut Lexer) -> Result<Self> {
        let mut list: Vec<Param> = Vec::new();
        while let Some(t) = lx.peek()? {
            if t.kind != Kind::Quoted {
                break;
            }
            let decl = lx.string("a parameter declaration")?;
            let mut words = decl.text.split_whitespace();
            let (Some(ty), Some(name), None) = (words.next(), words.next(), words.next()) else {
                return Err(decl.loc.error(format!(
                    "expected a parameter declaration \"type name\", found {}",
                    decl.shown()
                )));
            };
            let ty = match ty {
                "color" => "rgb",
                "point" => "point3",
                "vector" => "vector3",
                "normal" => "normal3",
                t if TYPES.contains(&t) => t,
                other => {
                    return Err(decl.loc.error(format!(
                        "unknown parameter type \"{other}\" (expected one of {})",
                        TYPES.join(", ")
                    )));
                }
            };
            if list.iter().any(|p| p.name == name) {
                return Err(decl.loc.error(format!("parameter \"{name}\" given twice")));
            }
            let mut raw: Vec<Token> = Vec::new();
            let first = lx.expect(&format!("a value of \"{}\"", decl.text))?;
            match first.kind {
                Kind::Open => loop {
                    let t = lx.expect("a value or ]")?;
                    match t.kind {
                        Kind::Close => break,
                        Kind::Open => {
                            return Err(t.loc.error("nested [ in a parameter's values"));
                        }
                        _ => raw.push(t),
                    }
                },
                Kind::Close => return Err(first.loc.error("unexpected ]")),
                _ => raw.push(first),
            }
            let values = values_of(ty, name, &raw, &decl.loc)?;
            list.push(Param {
                ty: ty.to_owned(),
                name: name.to_owned(),
                values,
                loc: decl.loc,
                used: Cell::new(false),
            });
        }
        Ok(Self { list })
    }

    fn get(&self, name: &str) -> Option<&Param> {
        let p = self.list.iter().find(|p| p.name == name)?;
        p.used.set(true);
        Some(p)
    }

    /// True if `name` is given (marks it read).
    pub fn has(&self, name: &str) -> bool {
        self.get(name).is_some()
    }

    /// Marks `name` read without using it (parameters that change nothing
    /// chiaro draws, such as the output file name).
    pub fn skip(&self, name: &str) {
        let _ = self.get(name);
    }

    /// The names of the parameters no getter read.
    pub fn unused(&self) -> Vec<String> {
        self.list
            .iter()
            .filter(|p| !p.used.get())
            .map(|p| format!("\"{} {}\"", p.ty, p.name))
            .collect()
    }

    fn numbers(&self, name: &str, types: &[&str]) -> Result<Option<(&Param, &[f32])>> {
        let Some(p) = self.get(name) else {
            return Ok(None);
        };
        match (&p.values, types.contains(&p.ty.as_str())) {
            (Values::Numbers(v), true) => Ok(Some((p, v))),
            _ => Err(p.loc.error(format!(
                "\"{name}\" must be of type {}, found \"{}\"",
                types.join(" or "),
                p.ty
            ))),
        }
    }

    /// A single `float` (pbrt-v3 files also write some as `integer`).
    pub fn float(&self, name: &str, default: f32) -> Result<f32> {
        match self.numbers(name, &["float", "integer"])? {
            None => Ok(default),
            Some((_, [v])) => Ok(*v),
            Some((p, v)) => Err(p
                .loc
                .error(format!("\"{name}\" takes one value, found {}", v.len()))),
        }
    }

    /// A single `integer`.
    pub fn int(&self, name: &str, default: i64) -> Result<i64> {
        match self.numbers(name, &["integer"])? {
            None => Ok(default),
            Some((_, [v])) => Ok(*v as i64),
            Some((p, v)) => Err(p
                .loc
                .error(format!("\"{name}\" takes one value, found {}", v.len()))),
        }
    }

    /// All values of a `float` parameter.
    pub fn floats(&self, name: &str) -> Result<Option<Vec<f32>>> {
        Ok(self.numbers(name, &["float"])?.map(|(_, v)| v.to_vec()))
    }

    /// All values of an `integer` parameter as indices (non-negative,
    /// within u32).
    pub fn indices(&self, name: &str) -> Result<Option<Vec<u32>>> {
        let Some((p, v)) = self.numbers(name, &["integer"])? else {
            return Ok(None);
        };
        v.iter()
            .map(|&x| {
                if x >= 0.0 && x <= u32::MAX as f32 && x.fract() == 0.0 {
                    Ok(x as u32)
                } else {
                    Err(p
                        .loc
                        .error(format!("\"{name}\": {x} is not a vertex index")))
                }
            })
            .collect::<Result<Vec<u32>>>()
            .map(Some)
    }

    /// A single `bool`.
    pub fn boolean(&self, name: &str, default: bool) -> Result<bool> {
        let Some(p) = self.get(name) else {
            return Ok(default);
        };
        match &p.values {
            Values::Bools(v) if v.len() == 1 => Ok(v[0]),
            _ => Err(p
                .loc
                .error(format!("\"{name}\" must be one bool (true or false)"))),
        }
    }

    /// A single `string`.
    pub fn string(&self, name: &str) -> Result<Option<String>> {
        let Some(p) = self.get(name) else {
            return Ok(None);
        };
        match (&p.values, p.ty.as_str()) {
            (Values::Strings(v), "string") if v.len() == 1 => Ok(Some(v[0].clone())),
            _ => Err(p.loc.error(format!("\"{name}\" must be one string"))),
        }
    }

    /// All strings of a `string` parameter.
    pub fn strings(&self, name: &str) -> Result<Option<Vec<String>>> {
        let Some(p) = self.get(name) else {
            return Ok(None);
        };
        match (&p.values, p.ty.as_str()) {
            (Values::Strings(v), "string") => Ok(Some(v.clone())),
            _ => Err(p.loc.error(format!("\"{name}\" must be strings"))),
        }
    }

    /// A 3-vector (`point3`, `vector3`, `normal3`, `rgb`) with one triple.
    pub fn vec3(&self, name: &str, default: Vec3) -> Result<Vec3> {
        match self.vec3s(name)? {
            None => Ok(default),
            Some(v) if v.len() == 1 => Ok(v[0]),
            Some(v) => Err(self
                .loc_of(name)
                .error(format!("\"{name}\" takes one triple, found {}", v.len()))),
        }
    }

    /// All triples of a `point3`, `vector3` or `normal3` parameter.
    pub fn vec3s(&self, name: &str) -> Result<Option<Vec<Vec3>>> {
        let Some((p, v)) = self.numbers(name, &["point3", "vector3", "normal3", "rgb"])? else {
            return Ok(None);
        };
        if v.len() % 3 != 0 {
            return Err(p.loc.error(format!(
                "\"{name}\" needs a multiple of 3 values, found {}",
                v.len()
            )));
        }
        Ok(Some(
            v.chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2]))
                .collect(),
        ))
    }

    /// All pairs of a `point2`, `vector2` or `float` parameter (pbrt-v3's
    /// `float uv`).
    pub fn vec2s(&self, name: &str) -> Result<Option<Vec<Vec2>>> {
        let Some((p, v)) = self.numbers(name, &["point2", "vector2", "float"])? else {
            return Ok(None);
        };
        if v.len() % 2 != 0 {
            return Err(p.loc.error(format!(
                "\"{name}\" needs an even number of values, found {}",
                v.len()
            )));
        }
        Ok(Some(
            v.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])).collect(),
        ))
    }

    /// A spectrum-valued parameter as written.
    pub fn spectrum(&self, name: &str) -> Result<Option<(Spectrum, Loc)>> {
        let Some(p) = self.get(name) else {
            return Ok(None);
        };
        let bad = |msg: &str| Err(p.loc.error(format!("\"{} {name}\": {msg}", p.ty)));
        let s = match (p.ty.as_str(), &p.values) {
            ("rgb", Values::Numbers(v)) if v.len() == 3 => {
                Spectrum::Rgb(Vec3::new(v[0], v[1], v[2]))
            }
            ("rgb", _) => return bad("needs three values"),
            ("float", Values::Numbers(v)) if v.len() == 1 => Spectrum::Rgb(Vec3::splat(v[0])),
            ("blackbody", Values::Numbers(v)) if v.len() == 1 => Spectrum::Blackbody(v[0], 1.0),
            ("blackbody", Values::Numbers(v)) if v.len() == 2 => Spectrum::Blackbody(v[0], v[1]),
            ("blackbody", _) => return bad("needs a temperature (and, in pbrt-v3, a scale)"),
            ("spectrum", Values::Strings(v)) if v.len() == 1 => Spectrum::Named(v[0].clone()),
            ("spectrum", Values::Numbers(v)) if v.len() >= 2 && v.len() % 2 == 0 => {
                Spectrum::Pairs(v.chunks_exact(2).map(|c| (c[0], c[1])).collect())
            }
            ("spectrum", _) => return bad("needs wavelength/value pairs or one name"),
            ("texture", Values::Strings(v)) if v.len() == 1 => Spectrum::Texture(v[0].clone()),
            _ => {
                return bad("expected an rgb, spectrum, blackbody, float or texture value");
            }
        };
        Ok(Some((s, p.loc.clone())))
    }

    /// Where parameter `name` is declared (the first parameter's place if
    /// it is not given).
    pub fn loc_of(&self, name: &str) -> Loc {
        self.list
            .iter()
            .find(|p| p.name == name)
            .or(self.list.first())
            .map_or_else(
                || Loc {
                    file: std::sync::Arc::new(std::path::PathBuf::new()),
                    line: 0,
                    column: 0,
                },
                |p| p.loc.clone(),
            )
    }
}

/// The values of a `ty name` parameter from its tokens.
fn values_of(ty: &str, name: &str, raw: &[Token], loc: &Loc) -> Result<Values> {
    match ty {
        "string" | "texture" => raw
            .iter()
            .map(|t| match t.kind {
                Kind::Quoted => Ok(t.text.clone()),
                _ => Err(t.loc.error(format!(
                    "\"{ty} {name}\": expected a quoted string, found {}",
                    t.shown()
                ))),
            })
            .collect::<Result<Vec<_>>>()
            .map(Values::Strings),
        "bool" => raw
            .iter()
            .map(|t| match t.text.as_str() {
                "true" => Ok(true),
                "false" => Ok(false),
                _ => Err(t.loc.error(format!(
                    "\"bool {name}\": expected true or false, found {}",
                    t.shown()
                ))),
            })
            .collect::<Result<Vec<_>>>()
            .map(Values::Bools),
        "spectrum" if raw.first().is_some_and(|t| t.kind == Kind::Quoted) => {
            if raw.len() != 1 {
                return Err(loc.error(format!("\"spectrum {name}\": one name expected")));
            }
            Ok(Values::Strings(vec![raw[0].text.clone()]))
        }
        _ => raw
            .iter()
            .map(|t| number_of(t, &format!("\"{ty} {name}\"")))
            .collect::<Result<Vec<_>>>()
            .map(Values::Numbers),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;
    use std::sync::Arc;

    fn read(text: &str) -> Result<Params> {
        let mut lx = Lexer::new(text, Arc::new(PathBuf::from("t.pbrt")));
        Params::read(&mut lx)
    }

    #[test]
    fn typed_values_and_unused() {
        let p = read(r#""float fov" 45 "rgb Kd" [0.1 0.2 0.3] "bool twosided" true "string filename" "a.ply" "integer indices" [0 1 2] "float extra" 1"#)
            .expect("test input");
        assert_eq!(p.float("fov", 90.0).expect("fov"), 45.0);
        assert_eq!(
            p.spectrum("Kd").expect("Kd").map(|s| s.0),
            Some(Spectrum::Rgb(Vec3::new(0.1, 0.2, 0.3)))
        );
        assert!(p.boolean("twosided", false).expect("bool"));
        assert_eq!(p.string("filename").expect("s").as_deref(), Some("a.ply"));
        assert_eq!(p.indices("indices").expect("i"), Some(vec![0, 1, 2]));
        assert_eq!(p.unused(), vec!["\"float extra\"".to_owned()]);
    }

    #[test]
    fn bad_parameters_name_their_place() {
        let e = read("\"float fov\" [ 1 \"x\" ]")
            .expect_err("string in floats")
            .to_string();
        assert!(e.contains("t.pbrt:1:17"), "{e}");
        let e = read("\"quaternion q\" 1").expect_err("type").to_string();
        assert!(
            e.contains("t.pbrt:1:1") && e.contains("unknown parameter type"),
            "{e}"
        );
        let e = read("\"float\" 1").expect_err("no name").to_string();
        assert!(e.contains("type name"), "{e}");
        let e = read("\"float a\" [ 1").expect_err("unclosed").to_string();
        assert!(e.contains("end of the file"), "{e}");
        let p = read("\"integer indices\" [ 0 -1 ]").expect("parses");
        let e = p.indices("indices").expect_err("negative").to_string();
        assert!(e.contains("t.pbrt:1:1"), "{e}");
        let e = read("\"float a\" 1 \"float a\" 2")
            .expect_err("twice")
            .to_string();
        assert!(e.contains("t.pbrt:1:13"), "{e}");
    }
}
