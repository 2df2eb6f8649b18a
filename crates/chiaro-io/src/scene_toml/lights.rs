//! `[[light]]`.

use super::raw::{AttenuationSpec, Opt, RawLight};
use super::{Ctx, Present, span_of};
use crate::Result;
use chiaro_core::Vec3;
use chiaro_core::scene::{AreaShape, Attenuation, Flap, Light, SpotLight};
use std::ops::Range;

impl Ctx<'_> {
    pub(super) fn light(&self, l: &RawLight) -> Result<Light> {
        let present: Present = vec![
            ("color", span_of(&l.color)),
            ("intensity", span_of(&l.intensity)),
            ("position", span_of(&l.position)),
            ("direction", span_of(&l.direction)),
            ("look_at", span_of(&l.look_at)),
            ("attenuation", span_of(&l.attenuation)),
            ("exponent", span_of(&l.exponent)),
            ("cone", span_of(&l.cone)),
            ("cone_softness", span_of(&l.cone_softness)),
            ("flaps", span_of(&l.flaps)),
            ("shape", span_of(&l.shape)),
            ("corner", span_of(&l.corner)),
            ("edge_u", span_of(&l.edge_u)),
            ("edge_v", span_of(&l.edge_v)),
            ("center", span_of(&l.center)),
            ("normal", span_of(&l.normal)),
            ("radius", span_of(&l.radius)),
            ("two_sided", span_of(&l.two_sided)),
        ];
        let kind = l.kind.get_ref().as_str();
        let tspan = l.kind.span();
        let color = match &l.color {
            Some(c) => self.non_negative3(c, "light color")?,
            None => Vec3::ONE,
        };
        let intensity = match &l.intensity {
            Some(i) => self.non_negative(i, "light intensity")?,
            None => 1.0,
        };
        let need = |v: &Opt<[f32; 3]>, what: &str| -> Result<Vec3> {
            v.as_ref()
                .map(|v| Vec3::from(*v.get_ref()))
                .ok_or_else(|| self.at(tspan.clone(), format!("a {kind} light needs `{what}`")))
        };
        let nonzero = |v: &Opt<[f32; 3]>, x: Vec3, what: &str| -> Result<Vec3> {
            x.try_normalize().ok_or_else(|| {
                self.at(
                    span_of(v).unwrap_or(tspan.clone()),
                    format!("`{what}` must not be the zero vector"),
                )
            })
        };
        let attenuation = match &l.attenuation {
            None => Attenuation::InverseSquare,
            Some(a) => match *a.get_ref() {
                AttenuationSpec::None => Attenuation::None,
                AttenuationSpec::InverseSquare => Attenuation::InverseSquare,
                AttenuationSpec::Empirical(e) => {
                    if e.c1 < 0.0 || e.c2 < 0.0 || e.c3 < 0.0 {
                        return Err(self.at(a.span(), "attenuation coefficients must be >= 0"));
                    }
                    Attenuation::Empirical {
                        c1: e.c1,
                        c2: e.c2,
                        c3: e.c3,
                    }
                }
            },
        };
        let common = ["color", "intensity"];
        match kind {
            "ambient" => {
                self.only("an ambient light", &present, &common)?;
                Ok(Light::Ambient { color, intensity })
            }
            "point" => {
                self.only(
                    "a point light",
                    &present,
                    &["color", "intensity", "position", "attenuation"],
                )?;
                Ok(Light::Point {
                    position: need(&l.position, "position")?,
                    color,
                    intensity,
                    attenuation,
                })
            }
            "directional" => {
                self.only(
                    "a directional light",
                    &present,
                    &["color", "intensity", "direction"],
                )?;
                let d = need(&l.direction, "direction")?;
                Ok(Light::Directional {
                    direction: nonzero(&l.direction, d, "direction")?,
                    color,
                    intensity,
                })
            }
            "spot" => {
                self.only(
                    "a spot light",
                    &present,
                    &[
                        "color",
                        "intensity",
                        "position",
                        "direction",
                        "look_at",
                        "attenuation",
                        "exponent",
                        "cone",
                        "cone_softness",
                        "flaps",
                    ],
                )?;
                let position = need(&l.position, "position")?;
                let (dir_field, dir) = match (&l.direction, &l.look_at) {
                    (Some(_), Some(b)) => {
                        return Err(self.at(
                            b.span(),
                            "give either `direction` or `look_at`, not both",
                        ));
                    }
                    (Some(_), None) => (&l.direction, need(&l.direction, "direction")?),
                    (None, Some(_)) => (&l.look_at, need(&l.look_at, "look_at")? - position),
                    (None, None) => {
                        return Err(self.at(tspan, "a spot light needs `direction` or `look_at`"));
                    }
                };
                let direction = nonzero(dir_field, dir, "direction")?;
                let exponent = match &l.exponent {
                    Some(e) => self.non_negative(e, "spot exponent")?,
                    None => 1.0,
                };
                // The cone's range is `Scene::validate`'s, placed at the key.
                let cone = l.cone.as_ref().map_or(90.0, |c| *c.get_ref());
                let softness = match &l.cone_softness {
                    Some(s) => {
                        let x = self.non_negative(s, "spot cone_softness")?;
                        // An out-of-range cone is reported by `Scene::validate`.
                        if x > cone && cone > 0.0 && cone <= 180.0 {
                            return Err(self.at(
                                s.span(),
                                format!("spot cone_softness {x} exceeds the cone {cone}"),
                            ));
                        }
                        x
                    }
                    None => 0.0,
                };
                let mut flaps = Vec::new();
                if let Some(fs) = &l.flaps {
                    for f in fs.get_ref() {
                        let Some(axis) = Vec3::from(f.axis).try_normalize() else {
                            return Err(self.at(fs.span(), "a flap `axis` must not be zero"));
                        };
                        if f.min > f.max {
                            return Err(self.at(
                                fs.span(),
                                format!("a flap needs min <= max, got {} > {}", f.min, f.max),
                            ));
                        }
                        flaps.push(Flap {
                            axis,
                            min: f.min,
                            max: f.max,
                        });
                    }
                }
                Ok(Light::Spot(SpotLight {
                    position,
                    direction,
                    color,
                    intensity,
                    attenuation,
                    exponent,
                    cone_degrees: cone,
                    cone_softness_degrees: softness,
                    flaps,
                }))
            }
            "area" => {
                let Some(shape) = &l.shape else {
                    return Err(self.at(
                        tspan,
                        "an area light needs `shape` = \"quad\", \"disk\" or \"sphere\"",
                    ));
                };
                let two_sided = l.two_sided.as_ref().is_some_and(|t| *t.get_ref());
                let shape = match shape.get_ref().as_str() {
                    "quad" => {
                        self.only(
                            "a quad area light",
                            &present,
                            &["color", "intensity", "shape", "corner", "edge_u", "edge_v", "two_sided"],
                        )?;
                        let edge_u = need(&l.edge_u, "edge_u")?;
                        let edge_v = need(&l.edge_v, "edge_v")?;
                        if edge_u.cross(edge_v).length_squared() == 0.0 {
                            return Err(self.at(
                                span_of(&l.edge_v).unwrap_or(tspan),
                                "edge_u and edge_v are parallel: the quad has no area",
                            ));
                        }
                        AreaShape::Quad {
                            corner: need(&l.corner, "corner")?,
                            edge_u,
                            edge_v,
                        }
                    }
                    "disk" => {
                        self.only(
                            "a disk area light",
                            &present,
                            &["color", "intensity", "shape", "center", "normal", "radius", "two_sided"],
                        )?;
                        let n = need(&l.normal, "normal")?;
                        AreaShape::Disk {
                            center: need(&l.center, "center")?,
                            normal: nonzero(&l.normal, n, "normal")?,
                            radius: self.radius(&l.radius, &tspan)?,
                        }
                    }
                    "sphere" => {
                        self.only(
                            "a sphere area light",
                            &present,
                            &["color", "intensity", "shape", "center", "radius", "two_sided"],
                        )?;
                        AreaShape::Sphere {
                            center: need(&l.center, "center")?,
                            radius: self.radius(&l.radius, &tspan)?,
                        }
                    }
                    other => {
                        return Err(self.at(
                            shape.span(),
                            format!(
                                "unknown area light shape {other:?}, expected one of: quad, disk, sphere"
                            ),
                        ));
                    }
                };
                Ok(Light::Area {
                    shape,
                    color,
                    intensity,
                    two_sided,
                })
            }
            other => Err(self.at(
                tspan,
                format!(
                    "unknown light type {other:?}, expected one of: ambient, point, directional, spot, area"
                ),
            )),
        }
    }

    pub(super) fn radius(&self, r: &Opt<f32>, fallback: &Range<usize>) -> Result<f32> {
        match r {
            Some(r) => self.finite_positive(r, "radius"),
            None => Err(self.at(fallback.clone(), "needs `radius`")),
        }
    }
}
