//! Materials: glTF metallic-roughness (and its extensions) to a chiaro
//! Torrance-Sparrow [`Material`] with a [`MetallicRoughness`].

use super::textures::UvSlots;
use super::{Builder, in_err};
use crate::Result;
use chiaro_core::scene::{
    AlphaMode, Material, MetallicRoughness, Occlusion, ReflectanceModel, Sidedness,
    TransparencyMode,
};
use chiaro_core::{Vec3, Vec4};

impl Builder<'_> {
    pub(super) fn material(&mut self, index: usize) -> Result<usize> {
        if let Some(&i) = self.material_map.get(&index) {
            return Ok(i);
        }
        let Some(gm) = self.doc.materials().nth(index) else {
            return Err(in_err(
                self.path,
                format!("materials[{index}]"),
                "missing material",
            ));
        };
        // The texCoord sets this material's textures read go to uv slots.
        self.uv_slots = UvSlots::of(&self.json, Some(index));
        let pbr = gm.pbr_metallic_roughness();
        let base = Vec4::from(pbr.base_color_factor());
        let base_rgb = if base.is_finite() {
            base.truncate().max(Vec3::ZERO)
        } else {
            Vec3::ONE
        };
        let mr = MetallicRoughness {
            base_color: base_rgb,
            metallic: pbr.metallic_factor(),
            roughness: pbr.roughness_factor(),
            texture: None,
        };
        let (diffuse, specular, roughness) =
            MetallicRoughness::coefficients(mr.base_color, mr.metallic, mr.roughness);
        let strength = gm.emissive_strength().unwrap_or(1.0).max(0.0);
        let mut mat = Material {
            name: gm
                .name()
                .map_or_else(|| format!("material{index}"), str::to_string),
            diffuse,
            specular,
            model: ReflectanceModel::TorranceSparrow,
            roughness,
            // Physically based: uniform ambient radiance Ia is reflected as
            // Ia kd (and Ia F0 off the specular lobe), not a tenth of it.
            ambient: Vec3::ONE,
            emission: Vec3::from(gm.emissive_factor()).max(Vec3::ZERO) * strength,
            // glTF 2.0 3.9.5: a single-sided material's back faces are culled.
            sidedness: if gm.double_sided() {
                Sidedness::TwoSided
            } else {
                Sidedness::Culled
            },
            emission_two_sided: gm.double_sided(),
            metallic_roughness: Some(mr),
            ..Material::default()
        };
        if let Some(info) = pbr.base_color_texture() {
            mat.texture = self.info_texture(&info, true);
        }
        if let Some(info) = pbr.metallic_roughness_texture() {
            let t = self.info_texture(&info, false);
            if let Some(m) = mat.metallic_roughness.as_mut() {
                m.texture = t;
            }
        }
        if let Some(info) = gm.emissive_texture() {
            mat.emission_texture = self.info_texture(&info, true);
        }
        if let Some(nt) = gm.normal_texture() {
            let at = format!("/materials/{index}/normalTexture");
            mat.normal_map = self.slot_texture(nt.texture(), nt.tex_coord(), &at, false);
        }
        if let Some(ot) = gm.occlusion_texture() {
            let at = format!("/materials/{index}/occlusionTexture");
            mat.occlusion = self
                .slot_texture(ot.texture(), ot.tex_coord(), &at, false)
                .map(|texture| Occlusion {
                    texture,
                    strength: ot.strength().clamp(0.0, 1.0),
                });
        }
        mat.alpha = if base.w.is_finite() {
            base.w.clamp(0.0, 1.0)
        } else {
            1.0
        };
        mat.alpha_mode = match gm.alpha_mode() {
            gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
            gltf::material::AlphaMode::Mask => AlphaMode::Mask {
                cutoff: gm.alpha_cutoff().unwrap_or(0.5),
            },
            gltf::material::AlphaMode::Blend => AlphaMode::Blend,
        };
        if mat.alpha_mode == AlphaMode::Blend {
            // The techniques draw the coverage as straight-through transmission
            // (per point in the surface layer: factor x texture x vertex alpha).
            mat.transmit = Vec3::splat(1.0 - mat.alpha);
            mat.ior = 1.0;
            mat.transparency = TransparencyMode::Interpolated;
        }
        // KHR_materials_transmission, _volume, _ior and _clearcoat.
        self.material_layers(index, &mut mat);
        if gm.unlit() {
            // KHR_materials_unlit: the base colour is emitted, nothing reflected.
            mat.emission = base_rgb;
            mat.emission_texture = mat.texture.take();
            mat.diffuse = Vec3::ZERO;
            mat.specular = Vec3::ZERO;
            mat.ambient = Vec3::ZERO;
            mat.metallic_roughness = None;
            mat.occlusion = None;
        }
        for c in [&mut mat.diffuse, &mut mat.specular, &mut mat.emission] {
            if !c.is_finite() {
                *c = Vec3::ZERO;
            }
        }
        self.out.materials.push(mat);
        let i = self.out.materials.len() - 1;
        self.material_map.insert(index, i);
        Ok(i)
    }
}
