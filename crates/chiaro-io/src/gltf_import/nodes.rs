//! The node hierarchy: each node's world transform, its camera, mesh
//! primitives and `KHR_lights_punctual` light (candela and lux to chiaro's `Ip`).

use super::{Builder, ConvertedPrimitive};
use crate::{ImportedObject, Result};
use chiaro_core::scene::{Attenuation, Camera, Light, NamedCamera, Projection, SpotLight};
use chiaro_core::{Mat4, Vec3};

impl Builder<'_> {
    pub(super) fn node(&mut self, node: &gltf::Node, world: Mat4) -> Result<()> {
        if let Some(cam) = node.camera() {
            // (projection, vertical fov, near, far): an orthographic
            // camera's `ymag` is its film's half-height (glTF 2.0, 5.13).
            let d = Camera::default();
            let lens = match cam.projection() {
                gltf::camera::Projection::Perspective(p) => {
                    let fov = p.yfov().to_degrees();
                    let near = if p.znear() > 0.0 { p.znear() } else { 0.01 };
                    let far = p
                        .zfar()
                        .filter(|f| f.is_finite() && *f > near)
                        .unwrap_or(near * 1.0e7);
                    (fov > 0.0 && fov < 180.0).then_some((Projection::Perspective, fov, near, far))
                }
                gltf::camera::Projection::Orthographic(o) => {
                    let half_height = o.ymag().abs();
                    let near = if o.znear() > 0.0 { o.znear() } else { 0.01 };
                    let far = o.zfar();
                    (half_height > 0.0 && half_height.is_finite() && far.is_finite() && far > near)
                        .then_some((
                            Projection::Orthographic { half_height },
                            d.fov_y_degrees,
                            near,
                            far,
                        ))
                }
            };
            let eye = world.transform_point3(Vec3::ZERO);
            let forward = world.transform_vector3(Vec3::NEG_Z).try_normalize();
            let up = world.transform_vector3(Vec3::Y).try_normalize();
            match (forward, up, lens) {
                (Some(f), Some(u), Some((projection, fov, near, far))) if eye.is_finite() => {
                    // Named after the camera, else its node, else its index.
                    let name = cam
                        .name()
                        .or(node.name())
                        .map_or_else(|| format!("camera{}", cam.index()), str::to_owned);
                    self.out.cameras.push(NamedCamera {
                        name,
                        camera: Camera {
                            eye,
                            look_at: eye + f,
                            up: u,
                            fov_y_degrees: fov,
                            near,
                            far,
                            projection,
                        },
                    });
                }
                _ => self
                    .note("a camera with a degenerate transform, fov or magnification was skipped"),
            }
        }
        if let Some(light) = node.light() {
            self.light(&light, world);
        }
        let Some(mesh) = node.mesh() else {
            return Ok(());
        };
        let skin = node.skin();
        for prim in mesh.primitives() {
            let key = (mesh.index(), prim.index());
            // A skinned primitive is posed for this node (not shared) and
            // placed by its joints, not by the node's transform.
            let (entry, matrix) = match &skin {
                Some(skin) => self.skinned_primitive(&mesh, &prim, skin, world)?,
                None => match self.mesh_cache.get(&key) {
                    Some(e) => (*e, world),
                    None => {
                        let e = self.primitive(&mesh, &prim)?;
                        self.mesh_cache.insert(key, e);
                        (e, world)
                    }
                },
            };
            if let Some((mesh_index, material)) = entry {
                let name = match (node.name(), mesh.name()) {
                    (Some(n), _) => format!("{n}#{}", prim.index()),
                    (None, Some(m)) => format!("{m}#{}", prim.index()),
                    (None, None) => format!("node{}#{}", node.index(), prim.index()),
                };
                self.out.objects.push(ImportedObject {
                    name,
                    mesh: mesh_index,
                    matrix,
                    material,
                });
            }
        }
        Ok(())
    }

    /// Reads primitive `prim` of a node with `skin` and poses it at rest
    /// ([`Builder::pose_skin`]); returns the converted primitive and its
    /// object matrix: the identity when posed, the node's `world` when the
    /// primitive has no joints and weights.
    fn skinned_primitive(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        skin: &gltf::Skin,
        world: Mat4,
    ) -> Result<(Option<ConvertedPrimitive>, Mat4)> {
        let Some((mut m, material)) = self.read_primitive(mesh, prim)? else {
            return Ok((None, world));
        };
        let loc = format!("meshes[{}].primitives[{}]", mesh.index(), prim.index());
        let posed = self.pose_skin(&mut m, prim, skin, &loc)?;
        self.out.meshes.push(m);
        let matrix = if posed { Mat4::IDENTITY } else { world };
        Ok((Some((self.out.meshes.len() - 1, material)), matrix))
    }

    pub(super) fn light(&mut self, light: &gltf::khr_lights_punctual::Light, world: Mat4) {
        use gltf::khr_lights_punctual::Kind;
        let color = Vec3::from(light.color());
        // Candela (or lux) to chiaro's Ip: divide by pi (module docs).
        let intensity = light.intensity() / std::f32::consts::PI;
        if !(color.is_finite() && intensity.is_finite() && intensity >= 0.0) {
            self.note("a light with invalid colour or intensity was skipped");
            return;
        }
        let position = world.transform_point3(Vec3::ZERO);
        let direction = world.transform_vector3(Vec3::NEG_Z).try_normalize();
        let Some(direction) = direction else {
            self.note("a light with a degenerate transform was skipped");
            return;
        };
        let l = match light.kind() {
            Kind::Directional => Light::Directional {
                direction,
                color,
                intensity,
            },
            Kind::Point => Light::Point {
                position,
                color,
                intensity,
                attenuation: Attenuation::InverseSquare,
            },
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => {
                let outer = outer_cone_angle.to_degrees().clamp(1e-3, 90.0);
                let inner = inner_cone_angle.to_degrees().clamp(0.0, outer);
                Light::Spot(SpotLight {
                    position,
                    direction,
                    color,
                    intensity,
                    attenuation: Attenuation::InverseSquare,
                    exponent: 0.0,
                    cone_degrees: outer,
                    cone_softness_degrees: outer - inner,
                    flaps: Vec::new(),
                })
            }
        };
        self.out.lights.push(l);
    }
}
