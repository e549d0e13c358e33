//! The highest and lowest value and the number of defined cells over square
//! windows of a grid layer, for several window sizes at once (000 §4.3's
//! height differences at l ∈ {1, 3, 6}).
//!
//! Max and min are idempotent, so a window's extreme is that of two
//! overlapping power-of-two runs that cover it: with `L_p[i]` the extreme
//! of `v[i .. i + 2^p]` (a sparse table, each level from the one before in
//! one pass: `L_p[i] = op(L_{p-1}[i], L_{p-1}[i + 2^(p-1)])`), the window
//! `[lo, hi]` of length n has `op(L_p[lo], L_p[hi + 1 - 2^p])`, p = ⌊log₂ n⌋.
//! Down the columns, every pass takes whole rows, so it vectorises across
//! the row; the levels are built once for all window sizes. Along the
//! rows, each row's levels are built in buffers that stay in L1, and the
//! windows wholly inside the row are two shifted slices. Counts are
//! differences of prefix sums, down the columns and then along the rows.
//! Windows are clipped at the layer's edges.

/// Scratch and results of [`WindowStats::compute`].
#[derive(Debug, Default)]
pub(crate) struct WindowStats {
    /// Per window size: highest defined value (-∞ where none), row-major.
    max: Vec<Vec<f32>>,
    /// Per window size: lowest defined value (+∞ where none).
    min: Vec<Vec<f32>>,
    /// Per window size: defined cells in the window.
    count: Vec<Vec<u32>>,
    /// Vertical sparse-table levels (level 0 is the layer itself).
    levels: Vec<Vec<f32>>,
    /// One scale's vertical extremes.
    vertical: Vec<f32>,
    /// A row's horizontal levels.
    row_levels: Vec<Vec<f32>>,
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

    /// The more extreme of two values that are never NaN (a plain
    /// comparison, so it vectorises).
    #[inline(always)]
    fn pick(self, a: f32, b: f32) -> f32 {
        match self {
            Self::Max => {
                if a > b {
                    a
                } else {
                    b
                }
            }
            Self::Min => {
                if a < b {
                    a
                } else {
                    b
                }
            }
        }
    }
}

/// ⌊log₂ n⌋ for n ≥ 1.
fn log2(n: usize) -> usize {
    (usize::BITS - 1 - n.leading_zeros()) as usize
}

/// `out[i] = op(a[i], b[i])`.
#[inline(always)]
fn combine(out: &mut [f32], a: &[f32], b: &[f32], op: Extreme) {
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
        debug_assert_eq!(layer.len(), n);
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
        let top = halves
            .iter()
            .map(|&h| log2((2 * h + 1).min(rows.max(cols))))
            .max()
            .unwrap_or(0);
        for op in [Extreme::Max, Extreme::Min] {
            self.vertical_levels(layer, cols, rows, top, op);
            for (k, &half) in halves.iter().enumerate() {
                self.vertical_window(cols, rows, half, op);
                let out = match op {
                    Extreme::Max => &mut self.max[k],
                    Extreme::Min => &mut self.min[k],
                };
                horizontal(&self.vertical, out, cols, half, op, &mut self.row_levels);
            }
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

    /// Levels 0..=top down the columns: level p row y is the extreme of
    /// rows y .. y + 2^p (clamped at the last row).
    #[inline(always)]
    fn vertical_levels(
        &mut self,
        layer: &[f32],
        cols: usize,
        rows: usize,
        top: usize,
        op: Extreme,
    ) {
        // Grown, never shrunk: the buffers are kept for the next image.
        if self.levels.len() <= top {
            self.levels.resize_with(top + 1, Vec::new);
        }
        let neutral = op.neutral();
        let first = &mut self.levels[0];
        first.clear();
        first.extend(layer.iter().map(|&v| if v.is_nan() { neutral } else { v }));
        for p in 1..=top {
            let (before, after) = self.levels.split_at_mut(p);
            let (prev, next) = (&before[p - 1], &mut after[0]);
            next.clear();
            next.resize(cols * rows, 0.0);
            let step = 1 << (p - 1);
            for y in 0..rows {
                let z = (y + step).min(rows - 1);
                combine(
                    &mut next[y * cols..(y + 1) * cols],
                    &prev[y * cols..(y + 1) * cols],
                    &prev[z * cols..(z + 1) * cols],
                    op,
                );
            }
        }
    }

    /// `self.vertical` = each cell's extreme over rows y - half ..= y + half.
    #[inline(always)]
    fn vertical_window(&mut self, cols: usize, rows: usize, half: usize, op: Extreme) {
        self.vertical.clear();
        self.vertical.resize(cols * rows, 0.0);
        for y in 0..rows {
            let (lo, hi) = (y.saturating_sub(half), (y + half).min(rows - 1));
            let p = log2(hi - lo + 1);
            let level = &self.levels[p];
            let b = hi + 1 - (1 << p);
            combine(
                &mut self.vertical[y * cols..(y + 1) * cols],
                &level[lo * cols..(lo + 1) * cols],
                &level[b * cols..(b + 1) * cols],
                op,
            );
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

/// `out` = each cell of `values` (`cols` wide) with its extreme over
/// columns x - half ..= x + half, row by row.
#[inline(always)]
fn horizontal(
    values: &[f32],
    out: &mut [f32],
    cols: usize,
    half: usize,
    op: Extreme,
    levels: &mut Vec<Vec<f32>>,
) {
    let top = log2((2 * half + 1).min(cols));
    if levels.len() <= top {
        levels.resize_with(top + 1, Vec::new);
    }
    for (line, source) in out.chunks_exact_mut(cols).zip(values.chunks_exact(cols)) {
        levels[0].clear();
        levels[0].extend_from_slice(source);
        for p in 1..=top {
            let (before, after) = levels.split_at_mut(p);
            let (prev, next) = (&before[p - 1], &mut after[0]);
            let step = 1 << (p - 1);
            next.clear();
            next.resize(cols, 0.0);
            let inner = cols.saturating_sub(step);
            combine(&mut next[..inner], &prev[..inner], &prev[step..], op);
            for x in inner..cols {
                next[x] = op.pick(prev[x], prev[cols - 1]);
            }
        }
        // Windows wholly inside the row: one level, two shifted slices.
        let full = 2 * half + 1;
        let (inner_from, inner_to) = if full <= cols {
            (half, cols - half)
        } else {
            (0, 0)
        };
        if inner_to > inner_from {
            let p = log2(full);
            let level = &levels[p];
            let width = inner_to - inner_from;
            let shift = full - (1 << p);
            combine(
                &mut line[inner_from..inner_to],
                &level[..width],
                &level[shift..shift + width],
                op,
            );
        }
        for x in (0..inner_from.min(cols)).chain(inner_to.max(inner_from)..cols) {
            let (lo, hi) = (x.saturating_sub(half), (x + half).min(cols - 1));
            let p = log2(hi - lo + 1);
            line[x] = op.pick(levels[p][lo], levels[p][hi + 1 - (1 << p)]);
        }
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
        let halves = [1, 3, 6];
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
                        "{cols}×{rows}, half {half}, cell {i}"
                    );
                }
            }
        }
    }
}
