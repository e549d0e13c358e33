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
//! Pixels without a return take no part and stay as they are; a pixel
//! whose window holds fewer than three returns is kept, and so are those
//! within half a window of the left and right edges (the rows' windows
//! shrink symmetrically at the top and bottom).

/// Histogram bins over `[0, max_range]`: 8192 bins are 4.9 mm at 40 m and
/// 12 mm at 100 m, well under range noise.
const BINS: usize = 8192;

/// The sliding-median outlier filter. Keeps its histogram between images.
#[derive(Debug, Clone)]
pub struct MedianOutliers {
    hist: Vec<u32>,
    /// Each pixel's bin ([`NONE`]: takes no part), computed once per image.
    bins: Vec<u16>,
}

/// The bin of a pixel that takes no part.
const NONE: u16 = u16::MAX;

impl Default for MedianOutliers {
    fn default() -> Self {
        Self {
            hist: vec![0; BINS],
            bins: Vec::new(),
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
        let rows = ranges.len() / cols;
        let scale = BINS as f32 / params.max_range;
        self.bins.clear();
        self.bins.extend(ranges.iter().map(|&r| {
            if r.is_finite() && r > 0.0 && r <= params.max_range {
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
            debug_assert_eq!(window.count, 0);
            window.median = 0;
            window.below = 0;
        }
        removed
    }
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
        let p = MedianParams {
            abs: bin,
            ..params()
        };
        let mut out = Vec::new();
        MedianOutliers::default().filter(&ranges, cols, &p, &mut out);
        // The median is known to half a bin: with abs = one bin, a return
        // two bins from its window's median is removed, the median kept.
        for row in 0..rows {
            for col in 0..cols {
                let r = ranges[row * cols + col];
                if !r.is_finite() || col < p.half_cols || col + p.half_cols >= cols {
                    continue;
                }
                let median = brute(&ranges, cols, row, col, &p);
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
