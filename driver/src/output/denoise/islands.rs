//! The islands of a denoising window, and images that hold one island's values alone.
//!
//! A denoiser that knows nothing of charts (an image network such as OIDN's) mixes whatever
//! pixels lie near each other in the atlas: another chart packed beside this one, or the
//! padding between them. The texel file keeps no chart ids, so the charts are found again in
//! each window from the texels' geometry: an **island** is a set of texels joined through
//! 4-neighbours that lie on one continuous surface ([`continuous`]: their normals within a
//! crease of each other, their positions no farther apart than one pixel step allows). Two
//! charts that touch in the atlas are two islands unless they continue each other in the world,
//! and a chart folded over a crease is two islands (the light changes across a crease).
//!
//! [`IslandImage`] lays one island out on a rectangle around it and fills every other pixel —
//! padding, empty atlas, other islands — with the value of the island texel nearest to it
//! (a breadth-first dilation, ties broken in a fixed order): the filter then sees the island
//! continue past its border in its own values and nothing else. Only the island's own pixels
//! are taken back.

use super::{NoisyTexel, Window};

/// The least cosine between the normals of two neighbouring texels of one island (about
/// 25°; the seam finder's crease, docs/lightmaps.md, "Seams").
pub const CREASE_COS: f32 = 0.9;

/// How far apart the centres of two neighbouring texels of one island may lie, in texel
/// spacings (with slack for stretched charts; the À-Trous filter's bound at one pixel).
pub const NEIGHBOUR_SPACINGS: f32 = 3.0;

/// Marks a pixel that belongs to no island.
pub const NO_ISLAND: u32 = u32::MAX;

/// Whether 4-neighbours `p` and `q` lie on one continuous surface.
#[must_use]
pub fn continuous(p: &NoisyTexel, q: &NoisyTexel) -> bool {
    if p.normal.dot(q.normal) < CREASE_COS {
        return false;
    }
    let spacing = p.spacing.max(q.spacing).max(f32::MIN_POSITIVE);
    (q.position - p.position).length() <= NEIGHBOUR_SPACINGS * spacing
}

/// The islands of a window: a label per pixel ([`NO_ISLAND`] where there is no texel) and
/// each island's bounding box.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Islands {
    /// Row-major labels, 0..`boxes.len()`, in the order of each island's first pixel.
    pub labels: Vec<u32>,
    /// Per island, `[x0, y0, x1, y1)` in window pixels.
    pub boxes: Vec<[usize; 4]>,
}

impl Islands {
    /// Labels the islands of `window` by flood fill (deterministic: islands are numbered in
    /// row-major order of their first pixel).
    #[must_use]
    pub fn of(window: &Window) -> Self {
        let (w, h) = (window.width, window.height);
        let mut labels = vec![NO_ISLAND; w * h];
        let mut boxes = Vec::new();
        let mut stack = Vec::new();
        for seed in 0..w * h {
            if labels[seed] != NO_ISLAND || window.texels[seed].is_none() {
                continue;
            }
            let label = boxes.len() as u32;
            let mut bounds = [seed % w, seed / w, seed % w + 1, seed / w + 1];
            labels[seed] = label;
            stack.push(seed);
            while let Some(i) = stack.pop() {
                let (x, y) = (i % w, i / w);
                bounds = [
                    bounds[0].min(x),
                    bounds[1].min(y),
                    bounds[2].max(x + 1),
                    bounds[3].max(y + 1),
                ];
                let p = window.texels[i]
                    .as_ref()
                    .expect("labelled pixels hold texels");
                for j in neighbours(x, y, w, h) {
                    if labels[j] != NO_ISLAND {
                        continue;
                    }
                    if window.texels[j].as_ref().is_some_and(|q| continuous(p, q)) {
                        labels[j] = label;
                        stack.push(j);
                    }
                }
            }
            boxes.push(bounds);
        }
        Self { labels, boxes }
    }
}

/// The 4-neighbours of `(x, y)` inside a `w` × `h` grid, as row-major indices.
fn neighbours(x: usize, y: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let i = y * w + x;
    [
        (x > 0).then(|| i - 1),
        (x + 1 < w).then(|| i + 1),
        (y > 0).then(|| i - w),
        (y + 1 < h).then(|| i + w),
    ]
    .into_iter()
    .flatten()
}

/// One island laid out on a rectangle of the window's pixel grid (it may reach past the
/// window), each pixel mapped to the island texel whose values it holds: its own where it is
/// one, else the nearest by breadth-first dilation.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct IslandImage {
    /// The rectangle's left column in window pixels (may be negative).
    pub x0: i64,
    /// Its top row (may be negative).
    pub y0: i64,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Per pixel of the rectangle, row-major: the window index of the island texel it copies.
    pub source: Vec<usize>,
    /// Per pixel of the rectangle: whether it is an island texel itself.
    pub own: Vec<bool>,
}

impl IslandImage {
    /// Island `island` of `islands` on its bounding box grown by `margin` pixels each side
    /// and rounded up to a multiple of `multiple` pixels.
    #[must_use]
    pub fn new(
        islands: &Islands,
        width: usize,
        island: usize,
        margin: usize,
        multiple: usize,
    ) -> Self {
        let b = islands.boxes[island];
        let round = |n: usize| n.div_ceil(multiple.max(1)) * multiple.max(1);
        let (iw, ih) = (
            round(b[2] - b[0] + 2 * margin),
            round(b[3] - b[1] + 2 * margin),
        );
        let (x0, y0) = (b[0] as i64 - margin as i64, b[1] as i64 - margin as i64);
        let mut source = vec![usize::MAX; iw * ih];
        let mut own = vec![false; iw * ih];
        let mut queue = std::collections::VecDeque::new();
        for y in b[1]..b[3] {
            for x in b[0]..b[2] {
                let i = y * width + x;
                if islands.labels[i] == island as u32 {
                    let at = (y as i64 - y0) as usize * iw + (x as i64 - x0) as usize;
                    source[at] = i;
                    own[at] = true;
                    queue.push_back(at);
                }
            }
        }
        while let Some(at) = queue.pop_front() {
            for next in neighbours(at % iw, at / iw, iw, ih) {
                if source[next] == usize::MAX {
                    source[next] = source[at];
                    queue.push_back(next);
                }
            }
        }
        Self {
            x0,
            y0,
            width: iw,
            height: ih,
            source,
            own,
        }
    }

    /// The image of one 3-channel layer, `value(window index)` at each pixel's source.
    #[must_use]
    pub fn layer(&self, value: impl Fn(usize) -> [f32; 3]) -> Vec<f32> {
        self.source.iter().flat_map(|&i| value(i)).collect()
    }

    /// The island's own pixels: (pixel of the rectangle, window index).
    pub fn own_pixels(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.own
            .iter()
            .enumerate()
            .filter(|(_, own)| **own)
            .map(|(at, _)| (at, self.source[at]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn texel(value: f32, position: Vec3, normal: Vec3) -> Option<NoisyTexel> {
        Some(NoisyTexel {
            rgb: [value; 3],
            variance: 0.0,
            position,
            normal,
            spacing: 0.1,
        })
    }

    /// A 12 × 6 window: columns 0–3 a floor chart, 4–5 padding, 6–11 a chart of the same
    /// normal 10 m away (side by side in the atlas only); row 5 of the first chart is a wall
    /// (a crease).
    fn two_charts() -> Window {
        let (w, h) = (12usize, 6usize);
        let texels = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let p = Vec3::new(x as f32 * 0.1, 0.0, y as f32 * 0.1);
                match x {
                    0..4 if y == 5 => texel(3.0, p + Vec3::Y * 0.1, Vec3::Z),
                    0..4 => texel(1.0, p, Vec3::Y),
                    4..6 => None,
                    _ => texel(9.0, p + Vec3::X * 10.0, Vec3::Y),
                }
            })
            .collect();
        Window {
            width: w,
            height: h,
            texels,
        }
    }

    #[test]
    fn charts_apart_in_the_world_and_across_a_crease_are_separate_islands() {
        let window = two_charts();
        let islands = Islands::of(&window);
        assert_eq!(
            islands.boxes,
            vec![[0, 0, 4, 5], [6, 0, 12, 6], [0, 5, 4, 6]]
        );
        assert_eq!(islands.labels[0], 0);
        assert_eq!(islands.labels[4], NO_ISLAND);
        assert_eq!(islands.labels[6], 1);
        assert_eq!(islands.labels[5 * 12], 2);
    }

    #[test]
    fn an_island_image_holds_its_own_values_alone() {
        let window = two_charts();
        let islands = Islands::of(&window);
        let image = IslandImage::new(&islands, 12, 0, 3, 8);
        assert_eq!(
            (image.x0, image.y0, image.width, image.height),
            (-3, -3, 16, 16)
        );
        let values = image.layer(|i| window.texels[i].unwrap().rgb);
        // Every pixel — padding, the far chart, the wall row, off the window — holds the
        // floor's 1.0.
        assert!(values.iter().all(|v| *v == 1.0), "{values:?}");
        let own: Vec<usize> = image.own_pixels().map(|(_, i)| i).collect();
        assert_eq!(own.len(), 20);
        assert!(own.iter().all(|&i| islands.labels[i] == 0));
        // The far chart's image copies its own border: window pixel (4, 0), in the padding,
        // holds its texel (6, 0).
        let far = IslandImage::new(&islands, 12, 1, 2, 1);
        assert_eq!((far.x0, far.y0), (4, -2));
        assert_eq!(far.source[2 * far.width], 6);
    }
}
