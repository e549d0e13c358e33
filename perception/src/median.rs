//! Outlier removal with a sliding median over a range image (000 §4.1:
//! "outliers are detected with a median filter and subsequently
//! eliminated"), in O(k) per pixel for a k × k window as in Huang et al.:
//! a histogram of the window's ranges slides along each row, k values
//! leaving and k entering per pixel, and the median bin is tracked by a
//! pointer that moves from the previous pixel's median.
//!
//! A return is an outlier when it lies farther from its window's median
//! than `abs + rel · median`; it is removed (becomes "no return"), never
//! replaced: the filter invents no range the sensor did not measure.
//!
//! Small windows (at most [`COUNTING_MAX`] pixels: the depth camera's 5 × 5,
//! a lidar's 1 × 5) are judged without finding the median at all, as
//! OpenCV's `medianBlur` switches method by kernel size. The test needs
//! only on which side of two bounds the median lies: with `m` the median
//! and `c` the return, `|c − m| > abs + rel·m` holds exactly when
//! `m > hi = (c + abs)/(1 − rel)` or `m < lo = (c − abs)/(1 + rel)`, and
//! the lower median of `n` values exceeds `hi` when at most `(n − 1)/2` of
//! them are `≤ hi` (and lies below `lo` when more than that are `< lo`).
//! Two counts per window pixel, done for a whole row of pixels at a time
//! (so they vectorise) and exact, with no histogram bins. Most pixels need
//! no count at all: where every return of the window lies within
//! `[lo, hi]`, so does the median, and a lowest and a highest per window
//! show that (`WindowBounds`); only blocks of eight pixels with one left
//! undecided are counted.
//! Pixels without a return take no part and stay as they are; a pixel
//! whose window holds fewer than three returns is kept, and so are those
//! within half a window of the left and right edges (the rows' windows
//! shrink symmetrically at the top and bottom).

/// Windows of at most this many pixels are judged by counting.
pub const COUNTING_MAX: usize = 49;

/// Histogram bins over `[0, max_range]`: 8192 bins are 4.9 mm at 40 m and
/// 12 mm at 100 m, well under range noise.
const BINS: usize = 8192;

/// The sliding-median outlier filter. Keeps its buffers between images.
#[derive(Debug, Clone)]
pub struct MedianOutliers {
    hist: Vec<u32>,
    /// Each pixel's bin ([`NONE`]: takes no part), computed once per image.
    bins: Vec<u16>,
    /// Counting: each pixel's range (NaN: takes no part), each row's
    /// bounds and counts.
    values: Vec<f32>,
    lo: Vec<f32>,
    hi: Vec<f32>,
    /// Counting: which pixels of a row only counts can decide.
    bounds: WindowBounds,
    below_lo: Vec<u32>,
    up_to_hi: Vec<u32>,
    valid: Vec<u32>,
}

/// The bin of a pixel that takes no part.
const NONE: u16 = u16::MAX;

impl Default for MedianOutliers {
    fn default() -> Self {
        Self {
            hist: vec![0; BINS],
            bins: Vec::new(),
            values: Vec::new(),
            lo: Vec::new(),
            hi: Vec::new(),
            bounds: WindowBounds::default(),
            below_lo: Vec::new(),
            up_to_hi: Vec::new(),
            valid: Vec::new(),
        }
    }
}

/// How the filter judges one image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MedianParams {
    /// The window is `2·half_rows + 1` rows by `2·half_cols + 1` columns
    /// (odd, so a pixel on a steadily receding ground row is its window's
    /// median and is never an outlier).
    pub half_rows: usize,
    pub half_cols: usize,
    /// Returns beyond this take no part (and are kept), m.
    pub max_range: f32,
    /// A return farther than `abs + rel · median` from its window's median
    /// is an outlier.
    pub abs: f32,
    pub rel: f32,
}

impl MedianParams {
    /// Whether a range is a return that takes part in the median.
    #[inline]
    fn takes_part(&self, r: f32) -> bool {
        r.is_finite() && r > 0.0 && r <= self.max_range
    }
}

/// The histogram of one window and its median pointer.
struct Window<'a> {
    hist: &'a mut [u32],
    scale: f32,
    count: u32,
    /// The median bin, and how many values lie in bins below it.
    median: usize,
    below: u32,
}

impl Window<'_> {
    #[inline]
    fn add(&mut self, bin: u16) {
        if bin != NONE {
            let b = usize::from(bin);
            self.hist[b] += 1;
            self.count += 1;
            self.below += u32::from(b < self.median);
        }
    }

    #[inline]
    fn remove(&mut self, bin: u16) {
        if bin != NONE {
            let b = usize::from(bin);
            self.hist[b] -= 1;
            self.count -= 1;
            self.below -= u32::from(b < self.median);
        }
    }

    /// The lower median of the window, m (the centre of its bin).
    #[inline]
    fn median(&mut self) -> f32 {
        let rank = (self.count - 1) / 2;
        while self.below > rank {
            self.median -= 1;
            self.below -= self.hist[self.median];
        }
        while self.below + self.hist[self.median] <= rank {
            self.below += self.hist[self.median];
            self.median += 1;
        }
        (self.median as f32 + 0.5) / self.scale
    }
}

impl MedianOutliers {
    /// Copies `ranges` (`rows × cols`, row-major) into `out` without its
    /// outliers (NaN in their place) and returns how many were removed.
    pub fn filter(
        &mut self,
        ranges: &[f32],
        cols: usize,
        params: &MedianParams,
        out: &mut Vec<f32>,
    ) -> u32 {
        out.clear();
        out.extend_from_slice(ranges);
        if cols == 0 || ranges.is_empty() || params.max_range.is_nan() || params.max_range <= 0.0 {
            return 0;
        }
        let (hr, hc) = (params.half_rows, params.half_cols);
        if hr == 0 && hc == 0 {
            // A window of one pixel is its own median.
            return 0;
        }
        if (2 * hr + 1) * (2 * hc + 1) <= COUNTING_MAX {
            return self.count(ranges, cols, params, out);
        }
        self.slide(ranges, cols, params, out)
    }

    /// [`MedianOutliers::filter`] by two counts per window pixel, with the
    /// AVX2 instruction set where the processor has it (eight lanes, not
    /// four; the same comparisons, so the same result).
    fn count(
        &mut self,
        ranges: &[f32],
        cols: usize,
        params: &MedianParams,
        out: &mut [f32],
    ) -> u32 {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { self.count_avx2(ranges, cols, params, out) };
        }
        self.count_portable(ranges, cols, params, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn count_avx2(
        &mut self,
        ranges: &[f32],
        cols: usize,
        params: &MedianParams,
        out: &mut [f32],
    ) -> u32 {
        // SAFETY: this function runs only where the processor has AVX2.
        self.count_rows(
            ranges,
            cols,
            params,
            out,
            |bounds, row| unsafe { bounds.compute_avx2(row) },
            |window| unsafe { window_counts_avx2(window) },
        )
    }

    fn count_portable(
        &mut self,
        ranges: &[f32],
        cols: usize,
        params: &MedianParams,
        out: &mut [f32],
    ) -> u32 {
        self.count_rows(
            ranges,
            cols,
            params,
            out,
            WindowBounds::compute,
            window_counts,
        )
    }

    /// The counting method, row by row, with `counts` doing each row's
    /// windows.
    #[inline(always)]
    fn count_rows(
        &mut self,
        ranges: &[f32],
        cols: usize,
        params: &MedianParams,
        out: &mut [f32],
        bounds: impl Fn(&mut WindowBounds, RowBounds<'_>),
        counts: impl Fn(RowWindows<'_>),
    ) -> u32 {
        let (hr, hc) = (params.half_rows, params.half_cols);
        let rows = ranges.len() / cols;
        if cols <= 2 * hc {
            return 0;
        }
        self.values.clear();
        self.values.extend(
            ranges
                .iter()
                .map(|&r| if params.takes_part(r) { r } else { f32::NAN }),
        );
        // Pixels `hc..cols - hc` of a row: pixel `j` of them has the
        // window columns `j..=j + 2·hc`.
        let inner = cols - 2 * hc;
        let (abs, rel) = (params.abs, params.rel);
        // Written by `counts` for the undecided pixels of each row.
        for counts in [&mut self.below_lo, &mut self.up_to_hi, &mut self.valid] {
            counts.resize(inner, 0);
        }
        let mut removed = 0;
        for row in 0..rows {
            let line = &self.values[row * cols..(row + 1) * cols];
            // NaN bounds count nothing: a pixel without a return is
            // skipped below anyway. (Sized first and written in place, so
            // that the divisions vectorise.)
            self.lo.resize(inner, 0.0);
            self.hi.resize(inner, 0.0);
            let centres = &line[hc..cols - hc];
            for ((lo, hi), &c) in self.lo.iter_mut().zip(self.hi.iter_mut()).zip(centres) {
                *lo = (c - abs) / (1.0 + rel);
                *hi = (c + abs) / (1.0 - rel);
            }
            if rel >= 1.0 {
                self.hi.fill(f32::INFINITY);
            }
            let hr = hr.min(row).min(rows - 1 - row);
            let window_rows = &self.values[(row - hr) * cols..(row + hr + 1) * cols];
            bounds(
                &mut self.bounds,
                RowBounds {
                    window_rows,
                    cols,
                    half_cols: hc,
                    lo: &self.lo,
                    hi: &self.hi,
                },
            );
            counts(RowWindows {
                values: window_rows,
                cols,
                half_cols: hc,
                first: 0,
                lo: &self.lo,
                hi: &self.hi,
                undecided: &self.bounds.undecided,
                below_lo: &mut self.below_lo,
                up_to_hi: &mut self.up_to_hi,
                valid: &mut self.valid,
            });
            // Eight pixels at a time past the decided ones.
            let undecided = &self.bounds.undecided;
            for j in (0..inner)
                .step_by(8)
                .filter(|&j| any_undecided(&undecided[j..(j + 8).min(inner)]))
            {
                for j in j..(j + 8).min(inner) {
                    if undecided[j] == 0 || line[hc + j].is_nan() {
                        continue;
                    }
                    let n = self.valid[j];
                    if n < 3 {
                        continue;
                    }
                    let rank = (n - 1) / 2;
                    if self.up_to_hi[j] <= rank || self.below_lo[j] > rank {
                        out[row * cols + hc + j] = f32::NAN;
                        removed += 1;
                    }
                }
            }
        }
        removed
    }

    /// [`MedianOutliers::filter`] by a sliding histogram (Huang et al.).
    fn slide(
        &mut self,
        ranges: &[f32],
        cols: usize,
        params: &MedianParams,
        out: &mut [f32],
    ) -> u32 {
        let (hr, hc) = (params.half_rows, params.half_cols);
        let rows = ranges.len() / cols;
        let scale = BINS as f32 / params.max_range;
        self.bins.clear();
        self.bins.extend(ranges.iter().map(|&r| {
            if params.takes_part(r) {
                ((r * scale) as usize).min(BINS - 1) as u16
            } else {
                NONE
            }
        }));
        let bins = &self.bins;
        let mut window = Window {
            hist: &mut self.hist,
            scale,
            count: 0,
            median: 0,
            below: 0,
        };
        let mut removed = 0;
        for row in 0..rows {
            // Symmetric about the row (fewer rows at the top and bottom): a
            // clipped window's median lies off a receding ground's row.
            let hr = hr.min(row).min(rows - 1 - row);
            let lines = row - hr..row + hr + 1;
            let column = |window: &mut Window, col: usize, add: bool| {
                for line in lines.clone() {
                    let bin = bins[line * cols + col];
                    if add {
                        window.add(bin);
                    } else {
                        window.remove(bin);
                    }
                }
            };
            for col in 0..=hc.min(cols - 1) {
                column(&mut window, col, true);
            }
            for col in 0..cols {
                if col > 0 {
                    if col + hc < cols {
                        column(&mut window, col + hc, true);
                    }
                    if let Some(leaving) = col.checked_sub(hc + 1) {
                        column(&mut window, leaving, false);
                    }
                }
                let range = ranges[row * cols + col];
                // A median of fewer than three returns shows nothing; nor
                // does one of a window clipped at the left or right edge.
                if bins[row * cols + col] == NONE
                    || window.count < 3
                    || col < hc
                    || col + hc >= cols
                {
                    continue;
                }
                let median = window.median();
                if (range - median).abs() > params.abs + params.rel * median {
                    out[row * cols + col] = f32::NAN;
                    removed += 1;
                }
            }
            for col in cols.saturating_sub(hc + 1)..cols {
                column(&mut window, col, false);
            }
            assert_eq!(window.count, 0);
            window.median = 0;
            window.below = 0;
        }
        removed
    }
}

/// Which pixels of a row the counting method must count for.
#[derive(Debug, Clone, Default)]
struct WindowBounds {
    /// Each column's lowest and highest return over the row's window rows
    /// (±∞ where none), then each inner pixel's over its whole window.
    column_low: Vec<f32>,
    column_high: Vec<f32>,
    window_low: Vec<f32>,
    window_high: Vec<f32>,
    /// Per inner pixel: 1 where its window holds a return outside its
    /// bounds `[lo, hi]`, so that only counts can decide it.
    undecided: Vec<u8>,
}

impl WindowBounds {
    /// Which pixels of a row only counts can decide: those whose window
    /// (`window_rows`, `cols` wide) holds a return outside their bounds.
    /// Where every return of the window lies within `[lo, hi]`, so does the
    /// median, and the pixel is kept without counting. On smooth ground
    /// that is most pixels; it costs a lowest and a highest per column and
    /// per window, with no division and no branch.
    #[inline(always)]
    fn compute(&mut self, row: RowBounds<'_>) {
        let RowBounds {
            window_rows,
            cols,
            half_cols: hc,
            lo,
            hi,
        } = row;
        let (low, high) = (&mut self.column_low, &mut self.column_high);
        low.clear();
        low.resize(cols, f32::INFINITY);
        high.clear();
        high.resize(cols, f32::NEG_INFINITY);
        for line in window_rows.chunks_exact(cols) {
            // `min` and `max` take the other operand where one is NaN.
            for ((l, h), &v) in low.iter_mut().zip(high.iter_mut()).zip(line) {
                *l = l.min(v);
                *h = h.max(v);
            }
        }
        let inner = cols - 2 * hc;
        self.window_low.clear();
        self.window_low.extend_from_slice(&low[..inner]);
        self.window_high.clear();
        self.window_high.extend_from_slice(&high[..inner]);
        for dc in 1..=2 * hc {
            let column = low[dc..][..inner].iter().zip(&high[dc..][..inner]);
            for ((l, h), (&cl, &ch)) in self
                .window_low
                .iter_mut()
                .zip(self.window_high.iter_mut())
                .zip(column)
            {
                *l = l.min(cl);
                *h = h.max(ch);
            }
        }
        self.undecided.resize(inner, 0);
        let windows = self.window_low.iter().zip(&self.window_high);
        for ((u, (&low, &high)), (&lo, &hi)) in self
            .undecided
            .iter_mut()
            .zip(windows)
            .zip(lo.iter().zip(hi))
        {
            *u = u8::from(low < lo) | u8::from(high > hi);
        }
    }

    /// [`WindowBounds::compute`] eight pixels at a time in AVX2 registers:
    /// `min`/`max` instructions return their second operand where either
    /// is NaN, so a pixel without a return never becomes an extreme (the
    /// portable version needs a NaN test per value for that). The same
    /// comparisons, so the same pixels are undecided.
    ///
    /// # Safety
    /// The processor must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn compute_avx2(&mut self, row: RowBounds<'_>) {
        use std::arch::x86_64::*;
        let RowBounds {
            window_rows,
            cols,
            half_cols: hc,
            lo,
            hi,
        } = row;
        let inner = cols - 2 * hc;
        assert!(lo.len() == inner && hi.len() == inner);
        let (low, high) = (&mut self.column_low, &mut self.column_high);
        low.resize(cols, 0.0);
        high.resize(cols, 0.0);
        let blocks = cols / 8;
        for c in (0..blocks).map(|b| 8 * b) {
            // SAFETY: c + 8 <= cols, the length of each window row and of
            // `low` and `high`.
            unsafe {
                let (mut l, mut h) = (
                    _mm256_set1_ps(f32::INFINITY),
                    _mm256_set1_ps(f32::NEG_INFINITY),
                );
                for line in window_rows.chunks_exact(cols) {
                    let v = _mm256_loadu_ps(line.as_ptr().add(c));
                    l = _mm256_min_ps(v, l);
                    h = _mm256_max_ps(v, h);
                }
                _mm256_storeu_ps(low.as_mut_ptr().add(c), l);
                _mm256_storeu_ps(high.as_mut_ptr().add(c), h);
            }
        }
        for c in 8 * blocks..cols {
            let (mut l, mut h) = (f32::INFINITY, f32::NEG_INFINITY);
            for line in window_rows.chunks_exact(cols) {
                (l, h) = (l.min(line[c]), h.max(line[c]));
            }
            (low[c], high[c]) = (l, h);
        }
        self.undecided.resize(inner, 0);
        let blocks = inner / 8;
        for j in (0..blocks).map(|b| 8 * b) {
            // SAFETY: j + 8 <= inner = lo.len() = hi.len(), and every
            // column read, j + dc + 7 with dc <= 2·hc, is below
            // inner + 2·hc = cols.
            let mask = unsafe {
                let (mut l, mut h) = (
                    _mm256_loadu_ps(low.as_ptr().add(j)),
                    _mm256_loadu_ps(high.as_ptr().add(j)),
                );
                for dc in 1..=2 * hc {
                    l = _mm256_min_ps(_mm256_loadu_ps(low.as_ptr().add(j + dc)), l);
                    h = _mm256_max_ps(_mm256_loadu_ps(high.as_ptr().add(j + dc)), h);
                }
                let below = _mm256_cmp_ps::<_CMP_LT_OQ>(l, _mm256_loadu_ps(lo.as_ptr().add(j)));
                let above = _mm256_cmp_ps::<_CMP_GT_OQ>(h, _mm256_loadu_ps(hi.as_ptr().add(j)));
                _mm256_movemask_ps(_mm256_or_ps(below, above)) as usize
            };
            self.undecided[j..j + 8].copy_from_slice(&SPREAD[mask].to_le_bytes());
        }
        for j in 8 * blocks..inner {
            let window = j..=j + 2 * hc;
            let l = low[window.clone()]
                .iter()
                .fold(f32::INFINITY, |a, &b| a.min(b));
            let h = high[window]
                .iter()
                .fold(f32::NEG_INFINITY, |a, &b| a.max(b));
            self.undecided[j] = u8::from(l < lo[j]) | u8::from(h > hi[j]);
        }
    }
}

/// Whether a block of `undecided` flags (eight, or the fewer at a row's
/// end) holds a pixel that only counts can decide; eight at once as one
/// word.
#[inline(always)]
fn any_undecided(block: &[u8]) -> bool {
    match <[u8; 8]>::try_from(block) {
        Ok(eight) => u64::from_ne_bytes(eight) != 0,
        Err(_) => block.iter().any(|&u| u != 0),
    }
}

/// Byte b of `SPREAD[m]` is bit b of m: eight comparison bits as eight
/// 0-or-1 bytes.
#[cfg(target_arch = "x86_64")]
const SPREAD: [u64; 256] = {
    let mut table = [0u64; 256];
    let mut m = 0;
    while m < 256 {
        let mut b = 0;
        while b < 8 {
            table[m] |= ((m as u64 >> b) & 1) << (8 * b);
            b += 1;
        }
        m += 1;
    }
    table
};

/// One row of pixels for [`WindowBounds`]: its window rows (`cols` wide)
/// and each inner pixel's bounds.
struct RowBounds<'a> {
    window_rows: &'a [f32],
    cols: usize,
    half_cols: usize,
    lo: &'a [f32],
    hi: &'a [f32],
}

/// One row's windows for the counting method: the window rows of
/// `values` (`cols` wide), and per inner pixel `first + j` of the row
/// (window columns `first + j ..= first + j + 2·half_cols`) its bounds and
/// the counts the counting functions write: window values below `lo[j]`,
/// up to `hi[j]`, and defined.
struct RowWindows<'a> {
    values: &'a [f32],
    cols: usize,
    half_cols: usize,
    /// The inner pixel the bounds and counts begin at.
    first: usize,
    lo: &'a [f32],
    hi: &'a [f32],
    /// 0 where the pixel is decided without its counts (they may be
    /// skipped), 1 where they decide it.
    undecided: &'a [u8],
    below_lo: &'a mut [u32],
    up_to_hi: &'a mut [u32],
    valid: &'a mut [u32],
}

/// Window value by window value, across the whole row of pixels (so each
/// pass is one plain loop the compiler vectorises).
#[inline(always)]
fn window_counts(w: RowWindows<'_>) {
    let inner = w.lo.len();
    for counts in [&mut *w.below_lo, &mut *w.up_to_hi, &mut *w.valid] {
        counts.fill(0);
    }
    for line in w.values.chunks_exact(w.cols) {
        for dc in 0..=2 * w.half_cols {
            let counts = w
                .below_lo
                .iter_mut()
                .zip(w.up_to_hi.iter_mut())
                .zip(w.valid.iter_mut());
            let bounds = w.lo.iter().zip(w.hi);
            for (((below, up_to), valid), (&v, (&lo, &hi))) in
                counts.zip(line[w.first + dc..][..inner].iter().zip(bounds))
            {
                *below += u32::from(v < lo);
                *up_to += u32::from(v <= hi);
                *valid += u32::from(!v.is_nan());
            }
        }
    }
}

/// [`window_counts`] eight pixels at a time with the counts held in
/// registers over the whole window (the compiler's version loads and
/// stores them once per window value); the same comparisons: ordered and
/// quiet, so NaN counts nothing.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn window_counts_avx2(w: RowWindows<'_>) {
    use std::arch::x86_64::*;
    let inner = w.lo.len();
    let width = 2 * w.half_cols + 1;
    let blocks = inner / 8;
    for block in 0..blocks {
        let j = 8 * block;
        if !any_undecided(&w.undecided[j..j + 8]) {
            continue;
        }
        assert_eq!(w.first, 0);
        assert!(inner + 2 * w.half_cols <= w.cols && w.hi.len() == inner);
        // SAFETY: j + 8 <= inner = lo.len() = hi.len(); every window value
        // read, a row's column j + dc + 7 with dc < width, lies within the
        // row: j + 7 + 2·half_cols < inner + 2·half_cols <= cols.
        unsafe {
            let lo = _mm256_loadu_ps(w.lo.as_ptr().add(j));
            let hi = _mm256_loadu_ps(w.hi.as_ptr().add(j));
            let (mut below, mut up_to, mut valid) = (
                _mm256_setzero_si256(),
                _mm256_setzero_si256(),
                _mm256_setzero_si256(),
            );
            for line in w.values.chunks_exact(w.cols) {
                let base = line.as_ptr().add(j);
                for dc in 0..width {
                    let v = _mm256_loadu_ps(base.add(dc));
                    // A true comparison is all ones: -1 as an integer.
                    let lt = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LT_OQ>(v, lo));
                    let le = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LE_OQ>(v, hi));
                    let ord = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_ORD_Q>(v, v));
                    below = _mm256_sub_epi32(below, lt);
                    up_to = _mm256_sub_epi32(up_to, le);
                    valid = _mm256_sub_epi32(valid, ord);
                }
            }
            for (counts, add) in [
                (&mut *w.below_lo, below),
                (&mut *w.up_to_hi, up_to),
                (&mut *w.valid, valid),
            ] {
                let at = counts.as_mut_ptr().add(j).cast::<__m256i>();
                _mm256_storeu_si256(at, add);
            }
        }
    }
    // The last pixels, fewer than eight.
    let done = 8 * blocks;
    window_counts(RowWindows {
        values: w.values,
        cols: w.cols,
        half_cols: w.half_cols,
        first: done,
        lo: &w.lo[done..],
        hi: &w.hi[done..],
        undecided: &w.undecided[done..],
        below_lo: &mut w.below_lo[done..],
        up_to_hi: &mut w.up_to_hi[done..],
        valid: &mut w.valid[done..],
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> MedianParams {
        MedianParams {
            half_rows: 1,
            half_cols: 2,
            max_range: 40.0,
            abs: 0.2,
            rel: 0.0,
        }
    }

    /// The brute-force median of the same window, for comparison.
    fn brute(ranges: &[f32], cols: usize, row: usize, col: usize, p: &MedianParams) -> f32 {
        let rows = ranges.len() / cols;
        let hr = p.half_rows.min(row).min(rows - 1 - row);
        let mut v: Vec<f32> = (row - hr..row + hr + 1)
            .flat_map(|r| {
                (col.saturating_sub(p.half_cols)..(col + p.half_cols + 1).min(cols))
                    .map(move |c| ranges[r * cols + c])
            })
            .filter(|r| r.is_finite() && *r > 0.0 && *r <= p.max_range)
            .collect();
        v.sort_by(f32::total_cmp);
        v[(v.len() - 1) / 2]
    }

    #[test]
    fn spikes_are_removed_and_a_receding_ground_is_kept() {
        let (rows, cols) = (9, 20);
        // Ground receding row by row, 0.4 m per row, with a spike and a gap.
        let mut ranges: Vec<f32> = (0..rows * cols)
            .map(|i| 5.0 + 0.4 * (i / cols) as f32 + 0.001 * (i % cols) as f32)
            .collect();
        ranges[4 * cols + 7] = 30.0;
        ranges[2 * cols + 3] = f32::NAN;
        let mut out = Vec::new();
        let removed = MedianOutliers::default().filter(&ranges, cols, &params(), &mut out);
        assert_eq!(removed, 1);
        assert!(out[4 * cols + 7].is_nan());
        assert!(out[2 * cols + 3].is_nan(), "a missing return stays missing");
        let kept = out.iter().filter(|r| r.is_finite()).count();
        assert_eq!(kept, rows * cols - 2);
    }

    #[test]
    fn the_sliding_median_is_the_window_median() {
        let (rows, cols) = (7, 31);
        // A deterministic jumble of ranges, some missing.
        let ranges: Vec<f32> = (0..rows * cols)
            .map(|i| {
                let x = (i as u32).wrapping_mul(2_654_435_761) >> 20;
                if x.is_multiple_of(11) {
                    f32::NAN
                } else {
                    1.0 + (x % 3000) as f32 * 0.01
                }
            })
            .collect();
        let bin = params().max_range / BINS as f32;
        // A window small enough to be counted, and one slid as a histogram.
        for (half_rows, half_cols, counted) in [(1, 2, true), (3, 4, false)] {
            let p = MedianParams {
                abs: bin,
                half_rows,
                half_cols,
                ..params()
            };
            assert_eq!(
                (2 * half_rows + 1) * (2 * half_cols + 1) <= COUNTING_MAX,
                counted
            );
            let mut out = Vec::new();
            MedianOutliers::default().filter(&ranges, cols, &p, &mut out);
            // The median is known to half a bin (exactly when counted): with
            // abs = one bin, a return two bins from its window's median is
            // removed, the median kept.
            check_against_brute(&ranges, cols, &p, &out, bin);
        }
    }

    #[test]
    fn counting_and_the_sliding_histogram_remove_the_same_returns() {
        let (rows, cols) = (9, 40);
        // Ground receding with noise, spikes and holes.
        let ranges: Vec<f32> = (0..rows * cols)
            .map(|i| {
                let x = (i as u32).wrapping_mul(2_654_435_761) >> 16;
                match x % 17 {
                    0 => f32::NAN,
                    1 => 2.0 + (x % 50) as f32,
                    _ => 5.0 + 0.4 * (i / cols) as f32 + (x % 100) as f32 * 0.002,
                }
            })
            .collect();
        let p = MedianParams {
            half_rows: 2,
            half_cols: 2,
            abs: 0.3,
            rel: 0.05,
            ..params()
        };
        let (mut counted, mut slid) = (Vec::new(), Vec::new());
        let mut filter = MedianOutliers::default();
        counted.extend_from_slice(&ranges);
        let removed_counting = filter.count(&ranges, cols, &p, &mut counted);
        slid.extend_from_slice(&ranges);
        let removed_sliding = filter.slide(&ranges, cols, &p, &mut slid);
        assert!(removed_counting > 10, "{removed_counting} removed");
        assert_eq!(removed_counting, removed_sliding);
        for (a, b) in counted.iter().zip(&slid) {
            assert_eq!(a.is_nan(), b.is_nan());
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_and_portable_counting_remove_the_same_returns() {
        if !crate::avx2_to_test("the AVX2 median") {
            return;
        }
        // Smooth receding ground (mostly decided without counts) with
        // spikes, holes and a jumbled patch (undecided), on widths that
        // leave every tail length of the eight-pixel blocks.
        for cols in [13, 20, 37, 64, 71] {
            let rows = 11;
            let ranges: Vec<f32> = (0..rows * cols)
                .map(|i| {
                    let (r, c) = (i / cols, i % cols);
                    let x = (i as u32).wrapping_mul(2_654_435_761) >> 16;
                    match x % 23 {
                        0 => f32::NAN,
                        1 => 1.0 + (x % 40) as f32,
                        _ if (3..6).contains(&r) && c < cols / 3 => 2.0 + (x % 900) as f32 * 0.01,
                        _ => 5.0 + 0.4 * r as f32 + (x % 100) as f32 * 0.002,
                    }
                })
                .collect();
            for (half_rows, half_cols) in [(0, 2), (1, 1), (2, 2), (3, 3), (1, 5)] {
                let p = MedianParams {
                    half_rows,
                    half_cols,
                    abs: 0.3,
                    rel: 0.05,
                    ..params()
                };
                let mut filter = MedianOutliers::default();
                let (mut avx2, mut portable) = (ranges.clone(), ranges.clone());
                // SAFETY: the processor has AVX2, checked above.
                let removed_avx2 = unsafe { filter.count_avx2(&ranges, cols, &p, &mut avx2) };
                let removed = filter.count_portable(&ranges, cols, &p, &mut portable);
                assert_eq!(removed_avx2, removed, "{cols} columns, {p:?}");
                let same = avx2
                    .iter()
                    .zip(&portable)
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(same, "{cols} columns, {p:?}");
                if cols >= 37 && half_cols <= 2 {
                    assert!(removed > 3, "{removed} removed: the test shows nothing");
                }
            }
        }
    }

    fn check_against_brute(ranges: &[f32], cols: usize, p: &MedianParams, out: &[f32], bin: f32) {
        let rows = ranges.len() / cols;
        for row in 0..rows {
            for col in 0..cols {
                let r = ranges[row * cols + col];
                if !r.is_finite() || col < p.half_cols || col + p.half_cols >= cols {
                    continue;
                }
                let median = brute(ranges, cols, row, col, p);
                let kept = out[row * cols + col].is_finite();
                if (r - median).abs() > 2.0 * bin {
                    assert!(!kept, "({row},{col}) {r} vs median {median} kept");
                }
                if r == median {
                    assert!(kept, "({row},{col}) is its window's median but was removed");
                }
            }
        }
    }
}
