//! The EXR encoder's side of a streamed page: channels of the page's names whose blocks
//! are read from the scratch file on request, and the one encoding every page is written
//! with (the same bytes every time).

use exr::block::{BlockIndex, UncompressedBlock};
use exr::image::write::channels::{ChannelsWriter, WritableChannels};
use exr::math::RoundingMode;
use exr::meta::attribute::{ChannelList, LevelMode};
use exr::meta::header::Header;
use exr::prelude::{AnyChannel, AnyChannels, Encoding, FlatSamples, LineOrder, SmallVec};

use super::*;

/// A [`PageStream`]'s channels as the EXR writer sees them: the header of an
/// [`AnyChannels`] of the same names, and blocks read from the scratch file on request.
pub(super) struct StreamedChannels<'p> {
    pub(super) page: &'p PageStream,
    /// The first scratch-file read that failed while the writer pulled blocks.
    pub(super) failure: &'p std::sync::Mutex<Option<PageWriteError>>,
}

impl StreamedChannels<'_> {
    /// The same channels, empty, for the header: what [`PageImage::encode`] describes.
    fn described(&self) -> AnyChannels<FlatSamples> {
        let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = self
            .page
            .names
            .iter()
            .map(|n| AnyChannel::new(n.as_str(), FlatSamples::F32(Vec::new())))
            .collect();
        AnyChannels::sort(list)
    }
}

impl<'p> WritableChannels<'p> for StreamedChannels<'p> {
    fn infer_channel_list(&self) -> ChannelList {
        self.described().infer_channel_list()
    }

    fn infer_level_modes(&self) -> (LevelMode, RoundingMode) {
        self.described().infer_level_modes()
    }

    type Writer = StreamedBlocks<'p>;

    fn create_writer(&'p self, _header: &Header) -> Self::Writer {
        StreamedBlocks {
            page: self.page,
            failure: self.failure,
        }
    }
}

/// Extracts EXR blocks from a [`PageStream`]'s scratch file.
pub(super) struct StreamedBlocks<'p> {
    page: &'p PageStream,
    failure: &'p std::sync::Mutex<Option<PageWriteError>>,
}

impl ChannelsWriter for StreamedBlocks<'_> {
    fn extract_uncompressed_block(&self, header: &Header, block: BlockIndex) -> Vec<u8> {
        let page = self.page;
        let stride = page.stride();
        let mut line = Vec::new();
        let mut line_y = usize::MAX;
        UncompressedBlock::collect_block_data_from_lines(&header.channels, block, |out| {
            let at = out.location.position;
            let n = out.location.sample_count;
            if at.y() != line_y {
                line.resize(n * stride, 0.0f32);
                // The writer cannot take an error from here: a failed read is kept, and
                // `encode` fails the page with it once the writer returns.
                if let Err(e) = page.read_records(at.y() * page.width + at.x(), &mut line) {
                    line.fill(0.0);
                    if let Ok(mut first) = self.failure.lock() {
                        first.get_or_insert(e);
                    }
                }
                line_y = at.y();
            }
            let slot = 1 + out.location.channel;
            out.write_samples(|i| line[i * stride + slot])
                .expect("a line of the block's own size");
        })
    }
}

/// The pages' encoding, one for the streamed writer and the in-memory reference. Blocks are
/// compressed in parallel; an increasing line order makes the writer put them in the file in
/// order, so the same lightmap is the same bytes whatever the threads' timing (with
/// `Unspecified` the order follows completion).
pub(super) fn page_encoding() -> Encoding {
    Encoding {
        line_order: LineOrder::Increasing,
        ..Encoding::SMALL_FAST_LOSSLESS
    }
}
