//! 2-D gradient noise (Perlin) and fractal sums of it, for procedural hills
//! and ground roughness. Deterministic from a seed.

use crate::numbers::floor;
use crate::rng::Rng;

/// Gradient noise with values in about [-1, 1].
#[derive(Debug, Clone)]
pub struct Noise {
    permutation: [u8; 512],
}

impl Noise {
    pub fn new(seed: u64) -> Self {
        let mut table: Vec<u8> = (0..=255).collect();
        let mut rng = Rng::new(seed);
        for i in (1..256).rev() {
            let j = (rng.next_u64() % (i as u64 + 1)) as usize;
            table.swap(i, j);
        }
        let mut permutation = [0u8; 512];
        for i in 0..512 {
            permutation[i] = table[i % 256];
        }
        Self { permutation }
    }

    /// The gradient at lattice point (ix, iy).
    fn grad(&self, ix: i64, iy: i64) -> (f64, f64) {
        let h = self.permutation
            [self.permutation[(ix & 255) as usize] as usize + (iy & 255) as usize]
            & 7;
        const D: f64 = std::f64::consts::FRAC_1_SQRT_2;
        match h {
            0 => (1.0, 0.0),
            1 => (-1.0, 0.0),
            2 => (0.0, 1.0),
            3 => (0.0, -1.0),
            4 => (D, D),
            5 => (-D, D),
            6 => (D, -D),
            _ => (-D, -D),
        }
    }

    fn gradient(&self, ix: i64, iy: i64, dx: f64, dy: f64) -> f64 {
        let (gx, gy) = self.grad(ix, iy);
        gx * dx + gy * dy
    }

    /// The noise along the row at `y` (lattice units): [`at`](Self::at)'s
    /// values bit for bit, with what does not change along a row (the
    /// lattice row, its fade, the gradients of the lattice cell) worked out
    /// once rather than per point. A tile's cells are built row by row.
    pub fn row(&self, y: f64) -> NoiseRow<'_> {
        let iy = floor(y);
        let dy = y - iy as f64;
        NoiseRow {
            noise: self,
            iy,
            dy,
            v: fade(dy),
            cell: None,
        }
    }

    /// [`fbm`](Self::fbm) along the row at `y`, for at most
    /// [`MAX_ROW_OCTAVES`] octaves.
    pub fn fbm_row(&self, y: f64, octaves: u32) -> FbmRow<'_> {
        let octaves = octaves.min(MAX_ROW_OCTAVES as u32) as usize;
        let mut frequency = 1.0;
        let rows = std::array::from_fn(|octave| {
            let offset = octave as f64 * 17.31;
            let row = (octave < octaves).then(|| self.row(y * frequency - offset));
            frequency *= 2.0;
            row
        });
        FbmRow { rows }
    }

    /// Noise at (x, y), in lattice units.
    pub fn at(&self, x: f64, y: f64) -> f64 {
        // Not `f64::floor`: a library call on x86-64's baseline, and every
        // cell of a tile takes several octaves of this (1.5 % of a lidar
        // mission's CPU).
        let (ix, iy) = (floor(x), floor(y));
        let (dx, dy) = (x - ix as f64, y - iy as f64);
        let (u, v) = (fade(dx), fade(dy));
        let n00 = self.gradient(ix, iy, dx, dy);
        let n10 = self.gradient(ix + 1, iy, dx - 1.0, dy);
        let n01 = self.gradient(ix, iy + 1, dx, dy - 1.0);
        let n11 = self.gradient(ix + 1, iy + 1, dx - 1.0, dy - 1.0);
        let a = n00 + u * (n10 - n00);
        let b = n01 + u * (n11 - n01);
        1.4 * (a + v * (b - a))
    }

    /// Fractal sum of `octaves` octaves, each at twice the frequency and
    /// half the amplitude, normalised to about [-1, 1].
    pub fn fbm(&self, x: f64, y: f64, octaves: u32) -> f64 {
        let (mut sum, mut amplitude, mut frequency, mut norm) = (0.0, 1.0, 1.0, 0.0);
        for octave in 0..octaves {
            let offset = octave as f64 * 17.31;
            sum += amplitude * self.at(x * frequency + offset, y * frequency - offset);
            norm += amplitude;
            amplitude *= 0.5;
            frequency *= 2.0;
        }
        sum / norm
    }
}

/// Perlin's fade curve, 6t⁵ − 15t⁴ + 10t³.
#[inline(always)]
fn fade(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// The most octaves [`Noise::fbm_row`] sums (the terrain's hills take 3).
pub const MAX_ROW_OCTAVES: usize = 3;

/// [`Noise::at`] along one row (see [`Noise::row`]).
pub struct NoiseRow<'a> {
    noise: &'a Noise,
    iy: i64,
    dy: f64,
    v: f64,
    /// The lattice column last asked for and its cell's four gradients.
    cell: Option<(i64, [(f64, f64); 4])>,
}

impl NoiseRow<'_> {
    /// Noise at (x, the row's y): [`Noise::at`]'s value, the same
    /// operations in the same order.
    pub fn at(&mut self, x: f64) -> f64 {
        let ix = floor(x);
        let dx = x - ix as f64;
        let u = fade(dx);
        let (noise, iy) = (self.noise, self.iy);
        let g = match self.cell {
            Some((at, g)) if at == ix => g,
            _ => {
                let g = [
                    noise.grad(ix, iy),
                    noise.grad(ix + 1, iy),
                    noise.grad(ix, iy + 1),
                    noise.grad(ix + 1, iy + 1),
                ];
                self.cell = Some((ix, g));
                g
            }
        };
        let (dy, v) = (self.dy, self.v);
        let n00 = g[0].0 * dx + g[0].1 * dy;
        let n10 = g[1].0 * (dx - 1.0) + g[1].1 * dy;
        let n01 = g[2].0 * dx + g[2].1 * (dy - 1.0);
        let n11 = g[3].0 * (dx - 1.0) + g[3].1 * (dy - 1.0);
        let a = n00 + u * (n10 - n00);
        let b = n01 + u * (n11 - n01);
        1.4 * (a + v * (b - a))
    }
}

/// [`Noise::fbm`] along one row (see [`Noise::fbm_row`]).
pub struct FbmRow<'a> {
    rows: [Option<NoiseRow<'a>>; MAX_ROW_OCTAVES],
}

impl FbmRow<'_> {
    /// [`Noise::fbm`] at (x, the row's y), bit for bit.
    pub fn at(&mut self, x: f64) -> f64 {
        let (mut sum, mut amplitude, mut frequency, mut norm) = (0.0, 1.0, 1.0, 0.0);
        for (octave, row) in self.rows.iter_mut().enumerate() {
            let Some(row) = row else { break };
            let offset = octave as f64 * 17.31;
            sum += amplitude * row.at(x * frequency + offset);
            norm += amplitude;
            amplitude *= 0.5;
            frequency *= 2.0;
        }
        sum / norm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_continuous_bounded_and_seeded() {
        let noise = Noise::new(7);
        let mut max_step: f64 = 0.0;
        let mut extreme: f64 = 0.0;
        for i in 0..2000 {
            let x = i as f64 * 0.01;
            let (a, b) = (noise.at(x, 0.37), noise.at(x + 0.001, 0.37));
            max_step = max_step.max((a - b).abs());
            extreme = extreme.max(a.abs());
        }
        assert!(max_step < 0.01, "continuous: {max_step}");
        assert!(extreme <= 1.2 && extreme > 0.3, "{extreme}");
        assert_eq!(noise.at(3.3, 4.4), Noise::new(7).at(3.3, 4.4));
        assert_ne!(noise.at(3.3, 4.4), Noise::new(8).at(3.3, 4.4));
        assert_eq!(noise.at(5.0, 9.0), 0.0, "zero on lattice points");
    }

    #[test]
    fn a_row_gives_the_noise_of_each_point_bit_for_bit() {
        let noise = Noise::new(11);
        for k in 0..40 {
            let y = -37.3 + k as f64 * 1.913;
            let mut row = noise.row(y);
            let mut fbm2 = noise.fbm_row(y, 2);
            let mut fbm3 = noise.fbm_row(y, 3);
            for i in 0..500 {
                let x = -61.7 + i as f64 * 0.0731;
                assert_eq!(row.at(x).to_bits(), noise.at(x, y).to_bits(), "({x}, {y})");
                assert_eq!(
                    fbm2.at(x).to_bits(),
                    noise.fbm(x, y, 2).to_bits(),
                    "({x}, {y})"
                );
                assert_eq!(
                    fbm3.at(x).to_bits(),
                    noise.fbm(x, y, 3).to_bits(),
                    "({x}, {y})"
                );
            }
        }
    }
}
