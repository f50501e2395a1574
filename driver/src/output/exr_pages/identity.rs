//! The identity a lightmap's pages carry in their EXR header: the bake and the texel file
//! they came from ([`LightmapIdentity`], [`read_identity`]), so `render`, `view` and
//! `probes` refuse a lightmap of another texel file.

use std::path::Path;

use exr::prelude::LayerAttributes;

/// The name of the one custom header attribute of a lightmap page: what made it, as lines of
/// `key: value` text ([`LightmapIdentity`]). One attribute, not one per key: the exr crate
/// writes custom attributes in its hash map's order, which changes from run to run, and a
/// bake's pages are the same bytes every time.
pub const IDENTITY_ATTRIBUTE: &str = "guidebake";

/// Key of [`LightmapIdentity`]: the texel file's identity
/// ([`TexelFile::identity`](crate::texels::TexelFile::identity)), 16 hex digits.
pub const TEXELS_KEY: &str = "texels";

/// Key of [`LightmapIdentity`]: the texel file's name, for messages.
pub const TEXEL_FILE_KEY: &str = "texel file";

/// What made a lightmap page, kept in its header ([`IDENTITY_ATTRIBUTE`]): the texel file's
/// identity and name, the scene's fingerprints, the lights, the settings and the guidebake
/// version, as `key: value` lines in the order given. `render` refuses a lightmap whose
/// texel file is not the one it is given.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LightmapIdentity {
    entries: Vec<(String, String)>,
}

impl LightmapIdentity {
    /// Adds `key: value` (a line break in either becomes a space; characters beyond Latin-1,
    /// which an EXR text cannot hold, become `?`).
    #[must_use]
    pub fn with(mut self, key: &str, value: &str) -> Self {
        let clean = |s: &str| -> String {
            s.chars()
                .map(|c| match c {
                    '\n' | '\r' => ' ',
                    c if u32::from(c) > 0xff => '?',
                    c => c,
                })
                .collect()
        };
        self.entries
            .push((clean(key).replace(':', " "), clean(value)));
        self
    }

    /// The value of `key`, if present.
    #[must_use]
    pub fn get(&self, key: &str) -> Option<&str> {
        self.entries
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The texel file's identity ([`TEXELS_KEY`]), if recorded.
    #[must_use]
    pub fn texels(&self) -> Option<u64> {
        self.get(TEXELS_KEY)
            .and_then(|v| u64::from_str_radix(v.trim(), 16).ok())
    }

    /// The entries in order.
    #[must_use]
    pub fn entries(&self) -> &[(String, String)] {
        &self.entries
    }

    fn to_text(&self) -> String {
        self.entries
            .iter()
            .map(|(k, v)| format!("{k}: {v}\n"))
            .collect()
    }

    fn parse(text: &str) -> Self {
        Self {
            entries: text
                .lines()
                .filter_map(|l| l.split_once(": "))
                .map(|(k, v)| (k.to_owned(), v.to_owned()))
                .collect(),
        }
    }

    pub(crate) fn write_into(&self, attributes: &mut LayerAttributes) {
        use exr::meta::attribute::{AttributeValue, Text};
        let text = Text::new_or_none(self.to_text()).expect("Latin-1 text (cleaned by `with`)");
        attributes
            .other
            .insert(Text::from(IDENTITY_ATTRIBUTE), AttributeValue::Text(text));
        attributes.software_name =
            Some(Text::from(concat!("guidebake ", env!("CARGO_PKG_VERSION"))));
    }
}

/// What made the lightmap page at `path`, from its header (the pixels are not read): `None`
/// for a page without [`IDENTITY_ATTRIBUTE`] (one an older guidebake wrote, or another tool).
///
/// # Errors
/// A message when the file cannot be read as an EXR.
pub fn read_identity(path: &Path) -> Result<Option<LightmapIdentity>, String> {
    use exr::meta::attribute::AttributeValue;
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| format!("cannot read the EXR header: {e}"))?;
    Ok(meta.headers.iter().find_map(|h| {
        match h.own_attributes.other.get(IDENTITY_ATTRIBUTE.as_bytes()) {
            Some(AttributeValue::Text(t)) => Some(LightmapIdentity::parse(
                &t.bytes().iter().map(|&b| char::from(b)).collect::<String>(),
            )),
            _ => None,
        }
    }))
}
