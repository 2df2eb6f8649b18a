//! Textures and samplers: `textureInfo` with `KHR_texture_transform`, wrap modes
//! and filters, and images read from a buffer view or a URI and decoded.

use super::Builder;
use super::buffers::{check_uri, decode_base64, percent_decode};
use chiaro_core::Vec2;
use chiaro_core::scene::{Filter, ImageTexture, Texture, TextureId, UvTransform, WrapMode};

impl Builder<'_> {
    /// The texture of a `textureInfo` (base colour, metallic-roughness,
    /// emissive, ...) of the material being converted, with its sampler,
    /// `KHR_texture_transform` and uv set.
    pub(super) fn info_texture(
        &mut self,
        info: &gltf::texture::Info,
        srgb: bool,
    ) -> Option<TextureId> {
        let transform = info.texture_transform().map(|t| UvTransform {
            offset: Vec2::from(t.offset()),
            rotation: t.rotation(),
            scale: Vec2::from(t.scale()),
        });
        let set = info
            .texture_transform()
            .and_then(|t| t.tex_coord())
            .unwrap_or(info.tex_coord());
        let slot = self.uv_slot(set);
        self.texture_ref(info.texture(), transform.unwrap_or_default(), slot, srgb)
    }

    /// The texture of the normal or occlusion texture at JSON pointer `at`
    /// (`/materials/3/normalTexture`): the gltf crate gives these no
    /// `KHR_texture_transform`, so it is read from the JSON, as the others'.
    pub(super) fn slot_texture(
        &mut self,
        tex: gltf::Texture,
        tex_coord: u32,
        at: &str,
        srgb: bool,
    ) -> Option<TextureId> {
        let (transform, set) = self
            .json
            .pointer(at)
            .map_or((UvTransform::default(), None), json_texture_transform);
        let slot = self.uv_slot(set.unwrap_or(tex_coord));
        self.texture_ref(tex, transform, slot, srgb)
    }

    /// The uv slot (0: the mesh's `uvs`, 1: its `uvs1`) of texCoord `set`
    /// under the current material's [`UvSlots`]; a set beyond its two is
    /// warned about once and reads the first.
    pub(super) fn uv_slot(&mut self, set: u32) -> u8 {
        match self.uv_slots.slot(set) {
            Some(s) => s,
            None => {
                self.note(format!(
                    "a material's textures use more than two texCoord sets: \
                     those on TEXCOORD_{set} read TEXCOORD_{}",
                    self.uv_slots.primary
                ));
                0
            }
        }
    }

    /// The texture of image `tex` seen through `transform` on uv slot
    /// `uv_set`, decoded once per distinct reference.
    pub(super) fn texture_ref(
        &mut self,
        tex: gltf::Texture,
        transform: UvTransform,
        uv_set: u8,
        srgb: bool,
    ) -> Option<TextureId> {
        let image = tex.source();
        let sampler = tex.sampler();
        let tb = [
            transform.offset.x,
            transform.offset.y,
            transform.rotation,
            transform.scale.x,
            transform.scale.y,
        ]
        .map(f32::to_bits);
        let key = (image.index(), srgb, sampler.index(), tb, uv_set);
        if let Some(t) = self.texture_map.get(&key) {
            return *t;
        }
        if !(transform.offset.is_finite()
            && transform.rotation.is_finite()
            && transform.scale.is_finite())
        {
            self.note("a non-finite KHR_texture_transform was ignored");
        }
        let wrap = |w| match w {
            gltf::texture::WrappingMode::ClampToEdge => WrapMode::Clamp,
            gltf::texture::WrappingMode::MirroredRepeat => WrapMode::Mirror,
            gltf::texture::WrappingMode::Repeat => WrapMode::Repeat,
        };
        use gltf::texture::{MagFilter, MinFilter};
        let mag_filter = match sampler.mag_filter() {
            Some(MagFilter::Nearest) => Filter::Nearest,
            _ => Filter::Linear,
        };
        // Unset: trilinear (the spec leaves it to the implementation).
        let (min_filter, mip_filter) = match sampler.min_filter() {
            Some(MinFilter::Nearest) => (Filter::Nearest, None),
            Some(MinFilter::Linear) => (Filter::Linear, None),
            Some(MinFilter::NearestMipmapNearest) => (Filter::Nearest, Some(Filter::Nearest)),
            Some(MinFilter::LinearMipmapNearest) => (Filter::Linear, Some(Filter::Nearest)),
            Some(MinFilter::NearestMipmapLinear) => (Filter::Nearest, Some(Filter::Linear)),
            Some(MinFilter::LinearMipmapLinear) | None => (Filter::Linear, Some(Filter::Linear)),
        };
        let id = match self.decode_image(&image, srgb) {
            Ok(mut img) => {
                img.wrap = wrap(sampler.wrap_s());
                img.wrap_t = Some(wrap(sampler.wrap_t()));
                img.mag_filter = mag_filter;
                img.min_filter = min_filter;
                img.mip_filter = mip_filter;
                img.uv_set = uv_set;
                if transform.offset.is_finite()
                    && transform.rotation.is_finite()
                    && transform.scale.is_finite()
                {
                    img.uv_transform = transform;
                }
                self.out.textures.push(Texture::Image(img));
                Some(TextureId(self.out.textures.len() as u32 - 1))
            }
            Err(msg) => {
                self.note(format!("images[{}]: {msg}: texture ignored", image.index()));
                None
            }
        };
        self.texture_map.insert(key, id);
        id
    }

    fn decode_image(
        &self,
        image: &gltf::Image,
        srgb: bool,
    ) -> std::result::Result<ImageTexture, String> {
        // The gltf crate's `source()` unwraps these (found by fuzzing).
        if let Some(json) = self.doc.as_json().images.get(image.index()) {
            if json.buffer_view.is_some() && json.mime_type.is_none() {
                return Err("an image in a buffer view needs a mimeType".into());
            }
            if json.buffer_view.is_none() && json.uri.is_none() {
                return Err("an image needs a uri or a bufferView".into());
            }
        }
        let (bytes, source): (Vec<u8>, String) = match image.source() {
            gltf::image::Source::View { view, .. } => {
                let data = self
                    .buffers
                    .get(view.buffer().index())
                    .ok_or("buffer missing")?;
                let end = view.offset().checked_add(view.length()).ok_or("bad view")?;
                let slice = data
                    .0
                    .get(view.offset()..end)
                    .ok_or("image view outside its buffer")?;
                (
                    slice.to_vec(),
                    format!("{}#images[{}]", self.path.display(), image.index()),
                )
            }
            gltf::image::Source::Uri { uri, .. } => {
                if let Some(rest) = uri.strip_prefix("data:") {
                    let b64 = rest
                        .split_once(";base64,")
                        .map(|(_, b)| b)
                        .ok_or("data URI is not base64")?;
                    (
                        decode_base64(b64)?,
                        format!("{}#images[{}]", self.path.display(), image.index()),
                    )
                } else {
                    check_uri(uri)?;
                    let base = self.base.ok_or("external image without a directory")?;
                    let rel = percent_decode(uri);
                    let p = base.join(&rel);
                    let bytes = crate::files::read_file_within(&p, self.budget, u64::MAX)
                        .map_err(|e| e.to_string())?;
                    (bytes, p.display().to_string())
                }
            }
        };
        crate::images::load_texture_bytes_within(&bytes, &source, srgb, self.budget)
            .map_err(|e| e.to_string())
    }
}

/// The `KHR_texture_transform` of a texture reference's JSON (`info`):
/// its offset, rotation and scale (defaults where absent or not numbers)
/// and its `texCoord` override.
pub(super) fn json_texture_transform(info: &serde_json::Value) -> (UvTransform, Option<u32>) {
    let Some(t) = info.pointer("/extensions/KHR_texture_transform") else {
        return (UvTransform::default(), None);
    };
    let num = |v: &serde_json::Value| v.as_f64().map(|x| x as f32);
    let pair = |key: &str, default: Vec2| match t.get(key).and_then(|v| v.as_array()) {
        Some(a) if a.len() == 2 => match (num(&a[0]), num(&a[1])) {
            (Some(x), Some(y)) => Vec2::new(x, y),
            _ => default,
        },
        _ => default,
    };
    let transform = UvTransform {
        offset: pair("offset", Vec2::ZERO),
        rotation: t.get("rotation").and_then(num).unwrap_or(0.0),
        scale: pair("scale", Vec2::ONE),
    };
    let set = t
        .get("texCoord")
        .and_then(serde_json::Value::as_u64)
        .map(|s| u32::try_from(s).unwrap_or(u32::MAX));
    (transform, set)
}

/// The texCoord sets the textures of a material (`material`, its JSON)
/// read, each reference's `KHR_texture_transform` override first: every
/// object under a key ending in `Texture` with an `index` is a texture
/// reference, so extensions' textures count too.
pub(super) fn texture_sets(material: &serde_json::Value, out: &mut Vec<u32>) {
    use serde_json::Value;
    match material {
        Value::Object(map) => {
            for (k, child) in map {
                if k.ends_with("Texture") && child.get("index").is_some() {
                    let base = child
                        .get("texCoord")
                        .and_then(Value::as_u64)
                        .map_or(0, |s| u32::try_from(s).unwrap_or(u32::MAX));
                    out.push(json_texture_transform(child).1.unwrap_or(base));
                }
                texture_sets(child, out);
            }
        }
        Value::Array(items) => items.iter().for_each(|c| texture_sets(c, out)),
        _ => {}
    }
}

/// Where a material's texCoord sets go on a chiaro mesh: the smallest set
/// its textures read becomes the mesh's `uvs` (slot 0), the next its
/// `uvs1` (slot 1); a material with one set needs no second.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct UvSlots {
    /// The set read into `uvs`.
    pub primary: u32,
    /// The set read into `uvs1`, when the material reads two.
    pub secondary: Option<u32>,
}

impl UvSlots {
    /// The slots of material `index` of the document `json` (set 0 alone
    /// for none or a missing material).
    pub(super) fn of(json: &serde_json::Value, index: Option<usize>) -> Self {
        let mut sets = Vec::new();
        if let Some(m) = index.and_then(|i| json.pointer(&format!("/materials/{i}"))) {
            texture_sets(m, &mut sets);
        }
        sets.sort_unstable();
        sets.dedup();
        Self {
            primary: sets.first().copied().unwrap_or(0),
            secondary: sets.get(1).copied(),
        }
    }

    /// The slot of texCoord `set`, `None` for a set beyond the two.
    pub(super) fn slot(self, set: u32) -> Option<u8> {
        if set == self.primary {
            Some(0)
        } else if Some(set) == self.secondary {
            Some(1)
        } else {
            None
        }
    }
}
