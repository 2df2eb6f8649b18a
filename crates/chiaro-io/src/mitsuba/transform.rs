//! `<transform>`: `translate`, `rotate`, `scale`, `matrix` and `lookat`,
//! each applied after the ones above it (`M = op * M`), as Mitsuba does.

use super::props::{number, numbers, vector_of};
use super::xml::Element;
use crate::Result;
use chiaro_core::{Mat4, Vec3, Vec4};

/// The matrix of a `<transform>` element (`world_from_object`).
pub fn parse_transform(el: &Element) -> Result<Mat4> {
    let mut m = Mat4::IDENTITY;
    for op in &el.children {
        let step = match op.tag.as_str() {
            "translate" => Mat4::from_translation(vector_of(op, Vec3::ZERO)?),
            "scale" => Mat4::from_scale(scale_of(op)?),
            "rotate" => rotation_of(op)?,
            "matrix" => matrix_of(op)?,
            "lookat" => lookat_of(op)?,
            other => {
                return Err(op.loc.error(format!(
                    "unknown transform <{other}> (expected translate, rotate, scale, matrix or lookat)"
                )));
            }
        };
        m = step * m;
    }
    if !m.is_finite() {
        return Err(el.loc.error("the transform is not finite"));
    }
    Ok(m)
}

/// `<scale value="s"/>` (uniform), `value="x, y, z"` or `x`/`y`/`z` (each 1
/// when missing).
fn scale_of(op: &Element) -> Result<Vec3> {
    if let Some(v) = op.attr("value") {
        let n = numbers(op, v)?;
        if let [s] = n.as_slice() {
            return Ok(Vec3::splat(*s));
        }
    }
    vector_of(op, Vec3::ONE)
}

/// `<rotate x="ax" y="ay" z="az" angle="deg"/>` or `value="ax, ay, az"`:
/// a right-handed rotation of `angle` degrees about the axis.
fn rotation_of(op: &Element) -> Result<Mat4> {
    let axis = vector_of(op, Vec3::ZERO)?;
    let angle = number(op, op.require("angle")?)?;
    let Some(axis) = axis.try_normalize() else {
        return Err(op
            .loc
            .error("<rotate> needs a non-zero axis (x, y, z or value)"));
    };
    Ok(Mat4::from_axis_angle(axis, angle.to_radians()))
}

/// `<matrix value="..."/>`: 16 numbers (4x4) or 9 (3x3, linear), row-major.
fn matrix_of(op: &Element) -> Result<Mat4> {
    let v = op.require("value")?;
    let n = numbers(op, v)?;
    match n.len() {
        16 => Ok(Mat4::from_cols_array(&std::array::from_fn(|i| {
            n[(i % 4) * 4 + i / 4]
        }))),
        9 => {
            let r = |i: usize| Vec4::new(n[i * 3], n[i * 3 + 1], n[i * 3 + 2], 0.0);
            Ok(Mat4::from_cols(r(0), r(1), r(2), Vec4::W).transpose())
        }
        k => Err(op
            .loc
            .error(format!("<matrix>: expected 16 numbers (or 9), found {k}"))),
    }
}

/// Mitsuba's `look_at`: columns `left = normalize(up x dir)`,
/// `up' = dir x left`, `dir`, `origin`, so that camera space looks down +z.
fn lookat_of(op: &Element) -> Result<Mat4> {
    let point = |name: &str| -> Result<Vec3> {
        let v = op.require(name)?;
        match numbers(op, v)?.as_slice() {
            [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
            _ => Err(op.loc.error(format!(
                "<lookat {name}>: expected three numbers, found {v:?}"
            ))),
        }
    };
    let origin = point("origin")?;
    let target = point("target")?;
    let up = match op.attr("up") {
        Some(_) => point("up")?,
        None => Vec3::Y,
    };
    let dir = (target - origin).try_normalize().ok_or_else(|| {
        op.loc
            .error("<lookat>: origin and target are the same point")
    })?;
    let left = up.cross(dir).try_normalize().ok_or_else(|| {
        op.loc
            .error("<lookat>: `up` is parallel to the viewing direction")
    })?;
    let new_up = dir.cross(left);
    Ok(Mat4::from_cols(
        left.extend(0.0),
        new_up.extend(0.0),
        dir.extend(0.0),
        origin.extend(1.0),
    ))
}

#[cfg(test)]
mod tests {
    use super::super::xml::parse_document;
    use super::*;
    use std::path::Path;

    fn transform(body: &str) -> Mat4 {
        let text =
            format!(r#"<scene version="3.0.0"><transform name="t">{body}</transform></scene>"#);
        let doc =
            parse_document(&text, Path::new("t.xml"), Path::new("."), &[]).expect("test input");
        parse_transform(&doc.elements[0]).expect("test input")
    }

    fn close(a: Mat4, b: Mat4) -> bool {
        a.abs_diff_eq(b, 1e-5)
    }

    #[test]
    fn translate_scale_rotate_in_order() {
        let m = transform(r#"<scale value="2"/><translate x="1" z="-3"/>"#);
        // Scale first, then translate.
        let want =
            Mat4::from_translation(Vec3::new(1.0, 0.0, -3.0)) * Mat4::from_scale(Vec3::splat(2.0));
        assert!(close(m, want), "{m:?}");
        // rotate 90 degrees about z: x goes to y.
        let r = transform(r#"<rotate z="1" angle="90"/>"#);
        assert!((r.transform_vector3(Vec3::X) - Vec3::Y).length() < 1e-6);
        // Rotation about y by angle given as a value axis.
        let r2 = transform(r#"<rotate value="0, 1, 0" angle="90"/>"#);
        assert!((r2.transform_vector3(Vec3::Z) - Vec3::X).length() < 1e-6);
        let s = transform(r#"<scale x="2" y="3"/>"#);
        assert!(close(s, Mat4::from_scale(Vec3::new(2.0, 3.0, 1.0))));
    }

    #[test]
    fn matrix_is_row_major() {
        let m = transform(r#"<matrix value="1 0 0 5  0 1 0 6  0 0 1 7  0 0 0 1"/>"#);
        assert_eq!(m.transform_point3(Vec3::ZERO), Vec3::new(5.0, 6.0, 7.0));
        let m3 = transform(r#"<matrix value="0 -1 0  1 0 0  0 0 1"/>"#);
        assert!((m3.transform_vector3(Vec3::X) - Vec3::Y).length() < 1e-6);
    }

    #[test]
    fn lookat_frame() {
        let m = transform(r#"<lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>"#);
        // Camera space +z looks at the target, +y is up, +x is the left.
        assert!((m.transform_vector3(Vec3::Z) - Vec3::NEG_Z).length() < 1e-6);
        assert!((m.transform_vector3(Vec3::Y) - Vec3::Y).length() < 1e-6);
        assert!((m.transform_vector3(Vec3::X) - Vec3::NEG_X).length() < 1e-6);
        assert_eq!(m.transform_point3(Vec3::ZERO), Vec3::new(0.0, 0.0, 5.0));
    }

    #[test]
    fn bad_transforms_are_errors() {
        for body in [
            r#"<rotate angle="10"/>"#,
            r#"<rotate x="1"/>"#,
            r#"<matrix value="1 2 3"/>"#,
            r#"<lookat origin="0,0,0" target="0,0,0"/>"#,
            r#"<skew value="1"/>"#,
            r#"<translate value="1, nan, 0"/>"#,
        ] {
            let text = format!(r#"<scene><transform name="t">{body}</transform></scene>"#);
            let doc =
                parse_document(&text, Path::new("t.xml"), Path::new("."), &[]).expect("test input");
            let e = parse_transform(&doc.elements[0])
                .expect_err("an error")
                .to_string();
            assert!(e.starts_with("t.xml:1:"), "{e}");
        }
    }
}
