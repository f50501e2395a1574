//! [`PageImage::dilate`] on a rolling window of rows ([`DilationWindow`]): what
//! [`super::PageStream`] pads its charts with, band by band on every core, in memory that
//! does not grow with the page's height.

use super::*;

/// Rows per band of [`PageStream`]'s parallel dilation (its halo is `passes` rows each side).
pub(super) const DILATION_BAND_ROWS: usize = 64;

/// Channels a [`DilationWindow`] fills at most (R, G, B and the 12 directional ones fit).
pub(super) const MAX_DILATED: usize = 32;

/// [`PageImage::dilate`] on a rolling window: level k holds the last rows after k passes; a
/// row of level k + 1 is made once level k has the row below it, so only `3 (passes + 1)`
/// rows are held, whatever the page's height. Each pass fills an unfilled pixel with the mean
/// of its filled 8-neighbours (summed in the same order as [`PageImage`], so the same bits).
pub(super) struct DilationWindow {
    passes: usize,
    width: usize,
    stride: usize,
    /// Record indices filled: R, G, B, then the dilated auxiliary channels.
    slots: Vec<usize>,
    /// The first row pushed: nothing lies above it.
    first: usize,
    /// Per level below the last: (row index, records, filled, changed) of its last two rows.
    levels: Vec<std::collections::VecDeque<WindowRow>>,
}

pub(super) struct WindowRow {
    y: usize,
    records: Vec<f32>,
    filled: Vec<bool>,
    changed: bool,
}

impl DilationWindow {
    /// A window whose first row is `first` (row 0 of the page, or the top of a band's halo).
    pub(super) fn starting_at(
        first: usize,
        passes: usize,
        width: usize,
        stride: usize,
        slots: Vec<usize>,
    ) -> Self {
        assert!(
            slots.len() <= MAX_DILATED,
            "at most {MAX_DILATED} dilated channels"
        );
        Self {
            passes,
            width,
            stride,
            slots,
            first,
            levels: (0..passes)
                .map(|_| std::collections::VecDeque::new())
                .collect(),
        }
    }

    /// Feeds row `y` of the undilated page (`last`: the page's last row); `emit` receives
    /// every finished row in order, with whether dilation changed it.
    pub(super) fn push(
        &mut self,
        y: usize,
        records: Vec<f32>,
        last: bool,
        emit: &mut dyn FnMut(usize, &[f32], bool),
    ) {
        let filled = records
            .chunks_exact(self.stride)
            .map(|r| r[COVERED] != 0.0)
            .collect();
        self.push_level(
            0,
            WindowRow {
                y,
                records,
                filled,
                changed: false,
            },
            last,
            emit,
        );
    }

    fn push_level(
        &mut self,
        level: usize,
        row: WindowRow,
        last: bool,
        emit: &mut dyn FnMut(usize, &[f32], bool),
    ) {
        if level == self.passes {
            emit(row.y, &row.records, row.changed);
            return;
        }
        let y = row.y;
        self.levels[level].push_back(row);
        let mut ready = Vec::new();
        if y > self.first {
            ready.push(self.next_row(level, y - 1));
        }
        if last {
            ready.push(self.next_row(level, y));
        }
        let window = &mut self.levels[level];
        while window.len() > 2 {
            window.pop_front();
        }
        let count = ready.len();
        for (i, next) in ready.into_iter().enumerate() {
            self.push_level(level + 1, next, last && i + 1 == count, emit);
        }
    }

    /// Row `y` after one more pass, from rows y − 1, y, y + 1 of `level`.
    fn next_row(&self, level: usize, y: usize) -> WindowRow {
        let window = &self.levels[level];
        let find = |row: usize| window.iter().find(|r| r.y == row);
        let centre = find(y).expect("the window holds the row");
        let rows: Vec<&WindowRow> = [y.checked_sub(1), Some(y), Some(y + 1)]
            .into_iter()
            .flatten()
            .filter_map(find)
            .collect();
        let mut next = WindowRow {
            y,
            records: centre.records.clone(),
            filled: centre.filled.clone(),
            changed: centre.changed,
        };
        for x in 0..self.width {
            if centre.filled[x] {
                continue;
            }
            let mut sums = [0.0f32; MAX_DILATED];
            let (sum, mut n) = (&mut sums[..self.slots.len()], 0u32);
            for row in &rows {
                for nx in x.saturating_sub(1)..=(x + 1).min(self.width - 1) {
                    if row.filled[nx] {
                        let record = &row.records[nx * self.stride..];
                        for (s, slot) in sum.iter_mut().zip(&self.slots) {
                            *s += record[*slot];
                        }
                        n += 1;
                    }
                }
            }
            if n > 0 {
                let record = &mut next.records[x * self.stride..];
                for (s, slot) in sum.iter().zip(&self.slots) {
                    record[*slot] = s / n as f32;
                }
                next.filled[x] = true;
                next.changed = true;
            }
        }
        next
    }
}
