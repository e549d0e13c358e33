//! Series of measurements (latencies, stage times) and their summaries.

use serde::Serialize;

/// Count, mean, median, 99th percentile and maximum of a series.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Summary {
    pub count: u64,
    pub mean: f64,
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

impl Summary {
    /// `value` for a table cell: two decimals, `-` when there is no sample.
    pub fn cell(&self, value: f64) -> String {
        if self.count == 0 {
            "-".to_owned()
        } else {
            format!("{value:.2}")
        }
    }
}

/// A series of measurements; percentiles over the newest [`Samples::KEPT`].
#[derive(Debug, Clone, Default)]
pub struct Samples {
    kept: Vec<f64>,
    next: usize,
    count: u64,
    sum: f64,
    max: f64,
}

impl Samples {
    pub const KEPT: usize = 1 << 16;

    pub fn add(&mut self, value: f64) {
        if self.kept.len() < Self::KEPT {
            self.kept.push(value);
        } else {
            self.kept[self.next] = value;
            self.next = (self.next + 1) % Self::KEPT;
        }
        self.count += 1;
        self.sum += value;
        self.max = if self.count == 1 {
            value
        } else {
            self.max.max(value)
        };
    }

    pub fn summary(&self) -> Summary {
        if self.count == 0 {
            return Summary::default();
        }
        let mut sorted = self.kept.clone();
        sorted.sort_by(f64::total_cmp);
        let at = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
        Summary {
            count: self.count,
            mean: self.sum / self.count as f64,
            p50: at(0.5),
            p99: at(0.99),
            max: self.max,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summaries_give_percentiles_of_the_newest_samples() {
        let mut s = Samples::default();
        assert_eq!(s.summary().count, 0);
        for v in 1..=100 {
            s.add(f64::from(v));
        }
        let sum = s.summary();
        assert_eq!(sum.count, 100);
        assert_eq!(sum.max, 100.0);
        assert!((sum.mean - 50.5).abs() < 1e-12);
        assert!((sum.p50 - 50.0).abs() <= 1.0);
        assert!((sum.p99 - 99.0).abs() <= 1.0);
        // Beyond KEPT, old samples leave the percentiles but not the count.
        for _ in 0..Samples::KEPT {
            s.add(1000.0);
        }
        let sum = s.summary();
        assert_eq!(sum.p50, 1000.0);
        assert_eq!(sum.count, 100 + Samples::KEPT as u64);
    }
}
