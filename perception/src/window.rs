//! The highest and lowest value and the number of defined cells over square
//! windows of a grid layer, for several window sizes at once (000 §4.3's
//! height differences at l ∈ {1, 3, 6}).
//!
//! Max and min are idempotent, so a window's extreme is that of any
//! windows that cover it, overlaps allowed: the window of half size `b` is
//! covered by the windows of half size `a < b` centred at offsets from
//! `-(b - a)` to `b - a`, at most `2a + 1` apart (1, 3, 6: the 3-window is
//! the 1-window at -1, 0, 1; the 7-window the 3-window at -2, 1, 2; the
//! 13-window the 7-window at -3, 3). Each scale is built from the one
//! before, along the rows and then down the columns, one shifted slice per
//! offset over the whole layer at once (so it vectorises). The layer is
//! padded with the extreme's neutral value by the largest half size, so a
//! window clipped at the layer's edge needs no case of its own, and every
//! shift stays inside the padded rows for the cells that are kept. Counts
//! are differences of prefix sums, down the columns and then along the
//! rows.

/// Scratch and results of [`WindowStats::compute`].
#[derive(Debug, Default)]
pub(crate) struct WindowStats {
    /// Per window size: highest defined value (-∞ where none), row-major.
    max: Vec<Vec<f32>>,
    /// Per window size: lowest defined value (+∞ where none).
    min: Vec<Vec<f32>>,
    /// Per window size: defined cells in the window.
    count: Vec<Vec<u32>>,
    /// The padded layer's extremes at the scale before and this one, and
    /// the pass along the rows between them.
    before: Vec<f32>,
    along: Vec<f32>,
    scale: Vec<f32>,
    /// Prefix sums of defined cells down the columns, `(rows + 1) × cols`.
    column_sums: Vec<u32>,
    /// One scale's vertical counts, and a row's prefix sums.
    vertical_count: Vec<u32>,
    row_sums: Vec<u32>,
}

#[derive(Clone, Copy)]
enum Extreme {
    Max,
    Min,
}

impl Extreme {
    /// What an undefined (NaN) cell becomes: never chosen.
    fn neutral(self) -> f32 {
        match self {
            Self::Max => f32::NEG_INFINITY,
            Self::Min => f32::INFINITY,
        }
    }
}

/// `out[i] = op(a[i], b[i])` (a select from two loads into a third
/// array, so that it vectorises).
#[inline(always)]
fn combine_into(out: &mut [f32], a: &[f32], b: &[f32], op: Extreme) {
    match op {
        Extreme::Max => {
            for ((o, &x), &y) in out.iter_mut().zip(a).zip(b) {
                *o = if x > y { x } else { y };
            }
        }
        Extreme::Min => {
            for ((o, &x), &y) in out.iter_mut().zip(a).zip(b) {
                *o = if x < y { x } else { y };
            }
        }
    }
}

/// `out[i] = op(out[i], a[i])` (never NaN here; `max` and `min` rather
/// than a select, which the compiler turns into masked stores).
#[inline(always)]
fn combine(out: &mut [f32], a: &[f32], op: Extreme) {
    match op {
        Extreme::Max => {
            for (o, &x) in out.iter_mut().zip(a) {
                *o = o.max(x);
            }
        }
        Extreme::Min => {
            for (o, &x) in out.iter_mut().zip(a) {
                *o = o.min(x);
            }
        }
    }
}

impl WindowStats {
    /// For the `cols × rows` layer `layer` (row-major, NaN = undefined) and
    /// each half size `halves[k]` (window `2h + 1` square), the extremes
    /// and counts of its defined cells, read with [`Self::max`],
    /// [`Self::min`], [`Self::count`].
    ///
    /// With AVX2 where the processor has it (the same operations, so the
    /// same results).
    pub fn compute(&mut self, layer: &[f32], cols: usize, rows: usize, halves: &[usize]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { self.compute_avx2(layer, cols, rows, halves) };
        }
        self.compute_portable(layer, cols, rows, halves);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn compute_avx2(&mut self, layer: &[f32], cols: usize, rows: usize, halves: &[usize]) {
        self.compute_portable(layer, cols, rows, halves);
    }

    #[inline(always)]
    fn compute_portable(&mut self, layer: &[f32], cols: usize, rows: usize, halves: &[usize]) {
        let n = cols * rows;
        assert_eq!(layer.len(), n);
        for out in [&mut self.max, &mut self.min] {
            out.resize_with(halves.len(), Vec::new);
            for o in out.iter_mut() {
                o.clear();
                o.resize(n, 0.0);
            }
        }
        self.count.resize_with(halves.len(), Vec::new);
        for o in &mut self.count {
            o.clear();
            o.resize(n, 0);
        }
        if n == 0 {
            return;
        }
        for op in [Extreme::Max, Extreme::Min] {
            self.extremes(layer, cols, rows, halves, op);
        }
        self.counts(layer, cols, rows, halves);
    }

    /// Highest defined value in each cell's window for `halves[k]`.
    pub fn max(&self, k: usize) -> &[f32] {
        &self.max[k]
    }

    /// Lowest defined value in each cell's window for `halves[k]`.
    pub fn min(&self, k: usize) -> &[f32] {
        &self.min[k]
    }

    /// Defined cells in each cell's window for `halves[k]`.
    pub fn count(&self, k: usize) -> &[u32] {
        &self.count[k]
    }

    /// Each window size's extreme of `op`, into `self.max` or `self.min`.
    /// `halves` must not decrease.
    #[inline(always)]
    fn extremes(&mut self, layer: &[f32], cols: usize, rows: usize, halves: &[usize], op: Extreme) {
        let pad = halves.iter().copied().max().unwrap_or(0);
        let (width, height) = (cols + 2 * pad, rows + 2 * pad);
        let neutral = op.neutral();
        let before = &mut self.before;
        before.clear();
        before.resize(width * height, neutral);
        for (y, line) in layer.chunks_exact(cols).enumerate() {
            let padded = &mut before[(y + pad) * width + pad..][..cols];
            for (p, &v) in padded.iter_mut().zip(line) {
                *p = if v.is_nan() { neutral } else { v };
            }
        }
        let mut half_before = 0;
        for (k, &half) in halves.iter().enumerate() {
            assert!(half >= half_before, "window sizes decrease: {halves:?}");
            let reach = half.saturating_sub(half_before);
            let step = 2 * half_before + 1;
            // Along the rows, then down the columns.
            cover(&self.before, &mut self.along, reach, step, 1, op);
            cover(&self.along, &mut self.scale, reach, step, width, op);
            std::mem::swap(&mut self.before, &mut self.scale);
            half_before = half;
            let out = match op {
                Extreme::Max => &mut self.max[k],
                Extreme::Min => &mut self.min[k],
            };
            for (y, line) in out.chunks_exact_mut(cols).enumerate() {
                line.copy_from_slice(&self.before[(y + pad) * width + pad..][..cols]);
            }
        }
    }

    /// Counts of defined cells: prefix sums down the columns (once), then
    /// per window size the vertical window's and each row's prefix sums.
    #[inline(always)]
    fn counts(&mut self, layer: &[f32], cols: usize, rows: usize, halves: &[usize]) {
        let sums = &mut self.column_sums;
        sums.clear();
        sums.resize((rows + 1) * cols, 0);
        for y in 0..rows {
            let (before, after) = sums.split_at_mut((y + 1) * cols);
            let prev = &before[y * cols..];
            for ((s, &p), &v) in after[..cols]
                .iter_mut()
                .zip(prev)
                .zip(&layer[y * cols..(y + 1) * cols])
            {
                *s = p + u32::from(!v.is_nan());
            }
        }
        for (k, &half) in halves.iter().enumerate() {
            let vertical = &mut self.vertical_count;
            vertical.clear();
            vertical.resize(cols * rows, 0);
            for y in 0..rows {
                let (lo, hi) = (y.saturating_sub(half), (y + half).min(rows - 1));
                let (top, bottom) = (&sums[lo * cols..][..cols], &sums[(hi + 1) * cols..][..cols]);
                for ((o, &t), &b) in vertical[y * cols..(y + 1) * cols]
                    .iter_mut()
                    .zip(top)
                    .zip(bottom)
                {
                    *o = b - t;
                }
            }
            let out = &mut self.count[k];
            let row_sums = &mut self.row_sums;
            row_sums.resize(cols + 1, 0);
            for y in 0..rows {
                let line = &vertical[y * cols..(y + 1) * cols];
                let mut total = 0;
                for (sum, &v) in row_sums[1..].iter_mut().zip(line) {
                    total += v;
                    *sum = total;
                }
                let out = &mut out[y * cols..(y + 1) * cols];
                // Windows wholly inside the row: two shifted slices.
                let (inner_from, inner_to) = if 2 * half < cols {
                    (half, cols - half)
                } else {
                    (0, 0)
                };
                let ends = row_sums.get(2 * half + 1..).unwrap_or_default();
                for ((o, &end), &start) in out[inner_from..inner_to]
                    .iter_mut()
                    .zip(ends)
                    .zip(&row_sums[..])
                {
                    *o = end - start;
                }
                for x in (0..inner_from).chain(inner_to.max(inner_from)..cols) {
                    let (lo, hi) = (x.saturating_sub(half), (x + half).min(cols - 1));
                    out[x] = row_sums[hi + 1] - row_sums[lo];
                }
            }
        }
    }
}

/// `target[i]` = the extreme of `source[i + d·stride]` over the offsets d
/// from `-reach` to `reach` at most `step` apart (`source`'s windows of
/// width `step` then cover the wider window). Where an offset leaves the
/// array, the cell is neutral (it lies in the padding, never read).
#[inline(always)]
fn cover(
    source: &[f32],
    target: &mut Vec<f32>,
    reach: usize,
    step: usize,
    stride: usize,
    op: Extreme,
) {
    let n = source.len();
    let neutral = op.neutral();
    // Only the margins need clearing: the rest is written below.
    target.resize(n, neutral);
    let margin = (reach * stride).min(n);
    target[..margin].fill(neutral);
    target[n - margin..].fill(neutral);
    if n <= 2 * margin {
        return;
    }
    let inner = n - 2 * margin;
    let out = &mut target[margin..][..inner];
    let at = |offset: usize| &source[offset * stride..][..inner];
    if reach == 0 {
        out.copy_from_slice(at(0));
        return;
    }
    // The first offset and the next in one pass, then every `step` up to
    // the last, `2·reach` (the window's `+reach`).
    let mut offset = step.min(2 * reach);
    combine_into(out, at(0), at(offset), op);
    while offset < 2 * reach {
        offset = (offset + step).min(2 * reach);
        combine(out, at(offset), op);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every cell's window by brute force.
    fn brute(layer: &[f32], cols: usize, rows: usize, half: usize) -> Vec<(f32, f32, u32)> {
        (0..cols * rows)
            .map(|i| {
                let (x, y) = (i % cols, i / cols);
                let (mut hi, mut lo, mut n) = (f32::NEG_INFINITY, f32::INFINITY, 0);
                for v in y.saturating_sub(half)..=(y + half).min(rows - 1) {
                    for u in x.saturating_sub(half)..=(x + half).min(cols - 1) {
                        let h = layer[v * cols + u];
                        if !h.is_nan() {
                            hi = hi.max(h);
                            lo = lo.min(h);
                            n += 1;
                        }
                    }
                }
                (hi, lo, n)
            })
            .collect()
    }

    #[test]
    fn windows_match_brute_force_on_every_shape_and_size() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut random = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let mut stats = WindowStats::default();
        // 000's scales; equal ones; far apart (many covering windows); one
        // wider than every shape.
        for halves in [[1, 3, 6], [1, 1, 2], [2, 5, 11], [1, 2, 50]] {
            // Shapes smaller than, equal to and larger than the windows.
            for (cols, rows) in [(1, 1), (1, 9), (9, 1), (5, 4), (13, 13), (14, 27), (40, 33)] {
                let layer: Vec<f32> = (0..cols * rows)
                    .map(|_| {
                        let r = random();
                        if r % 4 == 0 {
                            f32::NAN
                        } else {
                            (r >> 16) as f32 % 1000.0 * 0.01 - 5.0
                        }
                    })
                    .collect();
                stats.compute(&layer, cols, rows, &halves);
                for (k, &half) in halves.iter().enumerate() {
                    let expected = brute(&layer, cols, rows, half);
                    for (i, &(hi, lo, n)) in expected.iter().enumerate() {
                        assert_eq!(
                            (stats.max(k)[i], stats.min(k)[i], stats.count(k)[i]),
                            (hi, lo, n),
                            "{cols}×{rows}, half {half} of {halves:?}, cell {i}"
                        );
                    }
                }
            }
        }
    }
}
