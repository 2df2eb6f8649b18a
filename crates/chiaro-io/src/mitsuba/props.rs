//! A plugin's properties: typed reads of its child elements (`<float>`,
//! `<rgb>`, `<point>`, `<transform>`, ...) by name, remembering which were
//! read so that the rest can be reported as ignored.

use super::transform::parse_transform;
use super::xml::Element;
use crate::Result;
use chiaro_core::{Mat4, Vec3};
use std::cell::Cell;

/// The tags that are values (as opposed to nested plugins).
pub const VALUE_TAGS: [&str; 10] = [
    "integer",
    "float",
    "boolean",
    "string",
    "rgb",
    "spectrum",
    "point",
    "vector",
    "transform",
    "ref",
];

/// One plugin element with its properties' use tracked.
#[derive(Debug)]
pub struct Props<'a> {
    /// The plugin element.
    pub el: &'a Element,
    used: Vec<Cell<bool>>,
}

impl<'a> Props<'a> {
    /// The properties of `el`.
    pub fn new(el: &'a Element) -> Self {
        Self {
            el,
            used: el.children.iter().map(|_| Cell::new(false)).collect(),
        }
    }

    /// The child named `name` (any tag), marked as used.
    pub fn named(&self, name: &str) -> Option<&'a Element> {
        let i = self
            .el
            .children
            .iter()
            .position(|c| c.attr("name") == Some(name))?;
        self.used[i].set(true);
        Some(&self.el.children[i])
    }

    /// Unnamed child plugins with tag `tag` (nested `<bsdf>`, `<shape>`,
    /// unnamed `<ref>`), marked as used.
    pub fn children(&self, tag: &str) -> Vec<&'a Element> {
        let mut out = Vec::new();
        for (i, c) in self.el.children.iter().enumerate() {
            if c.tag == tag && (c.attr("name").is_none() || tag != "ref") {
                self.used[i].set(true);
                out.push(c);
            }
        }
        out
    }

    /// The nested BSDFs of a BSDF (`<bsdf>` children, then unnamed
    /// `<ref>`s), marked as used; an error unless there is one.
    pub fn nested_bsdfs(&self, ty: &str) -> Result<Vec<&'a Element>> {
        let mut all = self.children("bsdf");
        all.extend(self.children("ref"));
        if all.is_empty() {
            return Err(self
                .el
                .loc
                .error(format!("<bsdf type=\"{ty}\"> needs a nested <bsdf>")));
        }
        Ok(all)
    }

    /// The names (or tags) of children never read, with their elements.
    pub fn unused(&self) -> Vec<&'a Element> {
        self.el
            .children
            .iter()
            .zip(&self.used)
            .filter(|(_, u)| !u.get())
            .map(|(c, _)| c)
            .collect()
    }

    /// A `<float>` (or `<integer>`) named `name`, else `default`.
    pub fn float(&self, name: &str, default: f32) -> Result<f32> {
        match self.named(name) {
            None => Ok(default),
            Some(e) => match e.tag.as_str() {
                "float" | "integer" => number(e, e.require("value")?),
                _ => Err(e
                    .loc
                    .error(format!("`{name}` must be a <float>, found <{}>", e.tag))),
            },
        }
    }

    /// An `<integer>` named `name`, else `default`.
    pub fn int(&self, name: &str, default: i64) -> Result<i64> {
        match self.named(name) {
            None => Ok(default),
            Some(e) => {
                let v = e.require("value")?;
                if e.tag != "integer" {
                    return Err(e
                        .loc
                        .error(format!("`{name}` must be an <integer>, found <{}>", e.tag)));
                }
                v.trim().parse::<i64>().map_err(|_| {
                    e.loc
                        .error(format!("`{name}`: expected an integer, found {v:?}"))
                })
            }
        }
    }

    /// A `<boolean>` named `name`, else `default`.
    pub fn boolean(&self, name: &str, default: bool) -> Result<bool> {
        match self.named(name) {
            None => Ok(default),
            Some(e) => match e.require("value")?.trim() {
                "true" => Ok(true),
                "false" => Ok(false),
                v => Err(e
                    .loc
                    .error(format!("`{name}`: expected true or false, found {v:?}"))),
            },
        }
    }

    /// A `<string>` named `name`.
    pub fn string(&self, name: &str) -> Result<Option<&'a str>> {
        match self.named(name) {
            None => Ok(None),
            Some(e) => Ok(Some(e.require("value")?)),
        }
    }

    /// A `<point>` or `<vector>` named `name`, else `default`.
    pub fn vector(&self, name: &str, default: Vec3) -> Result<Vec3> {
        match self.named(name) {
            None => Ok(default),
            Some(e) => vector_of(e, Vec3::ZERO),
        }
    }

    /// A `<transform>` named `name` (`world_from_object`), else identity.
    pub fn transform(&self, name: &str) -> Result<Mat4> {
        match self.named(name) {
            None => Ok(Mat4::IDENTITY),
            Some(e) if e.tag == "transform" => parse_transform(e),
            Some(e) => Err(e
                .loc
                .error(format!("`{name}` must be a <transform>, found <{}>", e.tag))),
        }
    }
}

/// A decimal number, or an error at `e` naming what was found.
pub fn number(e: &Element, v: &str) -> Result<f32> {
    match v.trim().parse::<f32>() {
        Ok(x) if x.is_finite() => Ok(x),
        _ => Err(e.loc.error(format!(
            "<{}>: expected a finite number, found {v:?}",
            e.tag
        ))),
    }
}

/// A list of numbers separated by commas and/or white space.
pub fn numbers(e: &Element, v: &str) -> Result<Vec<f32>> {
    v.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .map(|s| number(e, s))
        .collect()
}

/// A 3-vector from `value="x, y, z"` (or one number for all three, if
/// `splat`) or from `x`, `y`, `z` attributes, each missing one `default`.
pub fn vector_of(e: &Element, default: Vec3) -> Result<Vec3> {
    if let Some(v) = e.attr("value") {
        let n = numbers(e, v)?;
        return match n.as_slice() {
            [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
            _ => Err(e.loc.error(format!(
                "<{}>: expected three numbers \"x, y, z\", found {v:?}",
                e.tag
            ))),
        };
    }
    let get = |k: &str, d: f32| e.attr(k).map_or(Ok(d), |v| number(e, v));
    Ok(Vec3::new(
        get("x", default.x)?,
        get("y", default.y)?,
        get("z", default.z)?,
    ))
}
