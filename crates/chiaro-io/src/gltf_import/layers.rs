//! The material extensions layered over metallic-roughness, read from each
//! material's JSON (the gltf crate has no clear coat): glTF
//! `KHR_materials_transmission` + `KHR_materials_volume` +
//! `KHR_materials_ior` become chiaro's glass, `KHR_materials_clearcoat` its
//! clear coat.
//!
//! - Transmission `t` (factor x R of the texture): that fraction of the
//!   dielectric's diffuse colour becomes the transmission colour of a
//!   Fresnel dielectric ([`Transmission::split`]); its roughness is the
//!   base roughness (rough transmission in the path tracer).
//! - With a volume of `thicknessFactor > 0` the surface bounds a medium of
//!   index `ior` (`KHR_materials_ior`, default 1.5) absorbing by Beer's law,
//!   `absorption = -ln(attenuationColor) / attenuationDistance` per unit
//!   length; without one it is thin-walled: light passes unbent (ior 1;
//!   blurred by a rough surface, `shading::dielectric`), reflected by the
//!   specular lobe.
//! - Clear coat: `clearcoatFactor` x R of `clearcoatTexture`, roughness
//!   `clearcoatRoughnessFactor` x G of `clearcoatRoughnessTexture`.
//!
//! Not read, with a warning: `thicknessTexture` (the geometry gives the
//! distance travelled), `clearcoatNormalTexture` (the coat uses the base
//! normal), texture transforms and `texCoord` of these textures.

use super::Builder;
use chiaro_core::Vec3;
use chiaro_core::scene::{AlphaMode, Clearcoat, Material, TextureId, Transmission};
use serde_json::Value;

/// Each material's `extensions` object, `Null` where it has none or the
/// JSON could not be read.
pub(super) fn material_extensions(json: Option<&Value>) -> Vec<Value> {
    json.and_then(|j| j.get("materials"))
        .and_then(Value::as_array)
        .map(|ms| {
            ms.iter()
                .map(|m| m.get("extensions").cloned().unwrap_or(Value::Null))
                .collect()
        })
        .unwrap_or_default()
}

/// The number at `key` of `v`, if it is one and finite.
fn number(v: &Value, key: &str) -> Option<f32> {
    v.get(key)
        .and_then(Value::as_f64)
        .map(|x| x as f32)
        .filter(|x| x.is_finite())
}

impl Builder<'_> {
    /// Applies the transmission, volume, ior and clear-coat extensions of
    /// material `index` to `mat` (its metallic-roughness already mapped).
    pub(super) fn material_layers(&mut self, index: usize, mat: &mut Material) {
        let Some(ext) = self.material_extensions.get(index).cloned() else {
            return;
        };
        if let Some(tr) = ext.get("KHR_materials_transmission") {
            self.transmission(tr, &ext, mat);
        }
        if let Some(cc) = ext.get("KHR_materials_clearcoat") {
            let factor = number(cc, "clearcoatFactor").unwrap_or(0.0).clamp(0.0, 1.0);
            if factor > 0.0 {
                let texture = self.layer_texture(cc.get("clearcoatTexture"));
                let roughness_texture = self.layer_texture(cc.get("clearcoatRoughnessTexture"));
                mat.clearcoat = Some(Clearcoat {
                    factor,
                    roughness: number(cc, "clearcoatRoughnessFactor")
                        .unwrap_or(0.0)
                        .clamp(0.0, 1.0),
                    texture,
                    roughness_texture,
                });
                if cc.get("clearcoatNormalTexture").is_some() {
                    self.note(
                        "KHR_materials_clearcoat: clearcoatNormalTexture is ignored \
                         (the coat uses the base normal)",
                    );
                }
            }
        }
    }

    /// `KHR_materials_transmission` `tr` (with the volume and ior of `ext`).
    fn transmission(&mut self, tr: &Value, ext: &Value, mat: &mut Material) {
        let factor = number(tr, "transmissionFactor")
            .unwrap_or(0.0)
            .clamp(0.0, 1.0);
        let texture = self.layer_texture(tr.get("transmissionTexture"));
        if factor <= 0.0 {
            return;
        }
        if mat.alpha_mode == AlphaMode::Blend {
            self.note(
                "KHR_materials_transmission on an alphaMode BLEND material is ignored \
                 (drawn by its coverage)",
            );
            return;
        }
        let Some(mr) = mat.metallic_roughness else {
            return;
        };
        let volume = ext.get("KHR_materials_volume");
        let thickness = volume
            .and_then(|v| number(v, "thicknessFactor"))
            .unwrap_or(0.0);
        let ior = ext
            .get("KHR_materials_ior")
            .and_then(|v| number(v, "ior"))
            .filter(|&x| x >= 1.0)
            .unwrap_or(1.5);
        if let Some(v) = volume.filter(|_| thickness > 0.0) {
            mat.ior = ior;
            // Beer's law: attenuationColor is what remains after attenuationDistance.
            let color = v
                .get("attenuationColor")
                .and_then(Value::as_array)
                .filter(|a| a.len() == 3)
                .map(|a| Vec3::from_array([0, 1, 2].map(|i| a[i].as_f64().unwrap_or(1.0) as f32)))
                .filter(|c| c.is_finite())
                .unwrap_or(Vec3::ONE);
            let distance = number(v, "attenuationDistance").filter(|&d| d > 0.0);
            if let Some(d) = distance {
                mat.absorption = -color.clamp(Vec3::splat(1e-4), Vec3::ONE).ln() / d;
            }
            if v.get("thicknessTexture").is_some() {
                self.note(
                    "KHR_materials_volume: thicknessTexture is ignored \
                     (the geometry gives the distance through the medium)",
                );
            }
        } else {
            // Thin-walled: no bending, no medium.
            mat.ior = 1.0;
        }
        mat.fresnel = true;
        mat.gltf_transmission = Some(Transmission { factor, texture });
        (mat.diffuse, mat.specular, mat.transmit) =
            Transmission::split(mat.diffuse, mat.specular, mr.metallic, factor, mat.ior);
    }

    /// The texture of a layer's textureInfo JSON (`{"index": n}`), linear.
    fn layer_texture(&mut self, info: Option<&Value>) -> Option<TextureId> {
        let index = info?.get("index")?.as_u64()? as usize;
        let Some(tex) = self.doc.textures().nth(index) else {
            self.note(format!(
                "a material extension names texture {index}, which does not exist; ignored"
            ));
            return None;
        };
        // The textureInfo's own texCoord and KHR_texture_transform, as for
        // the core material's slots.
        let (transform, set) = super::textures::json_texture_transform(info?);
        let tex_coord = info?.get("texCoord").and_then(Value::as_u64).unwrap_or(0) as u32;
        let slot = self.uv_slot(set.unwrap_or(tex_coord));
        self.texture_ref(tex, transform, slot, false)
    }
}

#[cfg(test)]
mod tests {
    use crate::gltf_import::load_gltf_slice;
    use chiaro_core::Vec3;
    use std::path::Path;

    /// One triangle per material of `materials` (a JSON array's items).
    fn file(materials: &str) -> String {
        let n = materials.matches("pbrMetallicRoughness").count();
        let meshes: Vec<String> = (0..n)
            .map(|i| {
                format!(
                    r#"{{"primitives": [{{"attributes": {{"POSITION": 0}}, "material": {i}}}]}}"#
                )
            })
            .collect();
        let nodes: Vec<String> = (0..n).map(|i| format!(r#"{{"mesh": {i}}}"#)).collect();
        let roots: Vec<String> = (0..n).map(|i| i.to_string()).collect();
        format!(
            r#"{{
              "asset": {{"version": "2.0"}},
              "extensionsUsed": ["KHR_materials_transmission", "KHR_materials_volume",
                "KHR_materials_ior", "KHR_materials_clearcoat"],
              "extensionsRequired": ["KHR_materials_transmission"],
              "scene": 0,
              "scenes": [{{"nodes": [{}]}}],
              "nodes": [{}],
              "materials": [{materials}],
              "meshes": [{}],
              "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                "min": [0, 0, 0], "max": [1, 1, 0]}}],
              "bufferViews": [{{"buffer": 0, "byteLength": 36}}],
              "buffers": [{{"byteLength": 36,
                "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}}]
            }}"#,
            roots.join(","),
            nodes.join(","),
            meshes.join(",")
        )
    }

    #[test]
    fn transmission_volume_ior_and_clearcoat_map_onto_glass_and_coat() {
        let f = file(
            r#"{"name": "vase", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 1, 1, 1],
                 "metallicFactor": 0, "roughnessFactor": 0.5},
               "extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.75},
                 "KHR_materials_ior": {"ior": 1.33},
                 "KHR_materials_volume": {"thicknessFactor": 1, "attenuationDistance": 2,
                   "attenuationColor": [0.5, 1, 0.25]}}},
               {"name": "thin", "pbrMetallicRoughness": {"metallicFactor": 0},
               "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1}}},
               {"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0, 0, 1],
                 "metallicFactor": 0},
               "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 0.9,
                 "clearcoatRoughnessFactor": 0.2}}}"#,
        );
        let imp = load_gltf_slice(f.as_bytes(), None, Path::new("g.gltf")).expect("loads");
        assert!(
            !imp.warnings.iter().any(|w| w.contains("not supported")),
            "{:#?}",
            imp.warnings
        );
        let m = |name: &str| {
            imp.materials
                .iter()
                .find(|m| m.name == name)
                .unwrap_or_else(|| panic!("{name}"))
        };
        let close = |a: Vec3, b: Vec3| (a - b).abs().max_element() < 1e-5;
        // Glass: 3/4 of the base colour transmitted, the Fresnel dielectric
        // reflecting that share of F0; Beer absorption -ln(c) / d.
        let vase = m("vase");
        assert!(vase.fresnel && vase.ior == 1.33);
        assert!(
            close(vase.transmit, Vec3::new(0.375, 0.75, 0.75)),
            "{}",
            vase.transmit
        );
        assert!(
            close(vase.diffuse, Vec3::new(0.125, 0.25, 0.25)),
            "{}",
            vase.diffuse
        );
        assert!(close(vase.specular, Vec3::splat(0.01)), "{}", vase.specular);
        let want = Vec3::new(2f32.ln() / 2.0, 0.0, 4f32.ln() / 2.0);
        assert!(close(vase.absorption, want), "{}", vase.absorption);
        // No volume: thin-walled, unbent and unabsorbing; the specular lobe kept.
        let thin = m("thin");
        assert!(thin.ior == 1.0 && thin.absorption == Vec3::ZERO);
        assert!(close(thin.transmit, Vec3::ONE) && close(thin.specular, Vec3::splat(0.04)));
        // The clear coat.
        let coat = m("paint").clearcoat.expect("a coat");
        assert_eq!((coat.factor, coat.roughness), (0.9, 0.2));
        assert_eq!(m("paint").transmit, Vec3::ZERO);
    }
}
