//! Textures and samplers: `textureInfo` with `KHR_texture_transform`, wrap modes
//! and filters, and images read from a buffer view or a URI and decoded.

use super::Builder;
use super::buffers::{check_uri, decode_base64, percent_decode};
use chiaro_core::Vec2;
use chiaro_core::scene::{Filter, ImageTexture, Texture, TextureId, UvTransform, WrapMode};

impl Builder<'_> {
    /// The texture of a `textureInfo` (base colour, metallic-roughness,
    /// emissive), with its sampler and `KHR_texture_transform`.
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
        self.texture_info(info.texture(), transform.unwrap_or_default(), srgb)
    }

    pub(super) fn texture_info(
        &mut self,
        tex: gltf::Texture,
        transform: UvTransform,
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
        let key = (image.index(), srgb, sampler.index(), tb);
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
