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

    fn gradient(&self, ix: i64, iy: i64, dx: f64, dy: f64) -> f64 {
        let h = self.permutation
            [self.permutation[(ix & 255) as usize] as usize + (iy & 255) as usize]
            & 7;
        const D: f64 = std::f64::consts::FRAC_1_SQRT_2;
        let (gx, gy) = match h {
            0 => (1.0, 0.0),
            1 => (-1.0, 0.0),
            2 => (0.0, 1.0),
            3 => (0.0, -1.0),
            4 => (D, D),
            5 => (-D, D),
            6 => (D, -D),
            _ => (-D, -D),
        };
        gx * dx + gy * dy
    }

    /// Noise at (x, y), in lattice units.
    pub fn at(&self, x: f64, y: f64) -> f64 {
        // Not `f64::floor`: a library call on x86-64's baseline, and every
        // cell of a tile takes several octaves of this (1.5 % of a lidar
        // mission's CPU).
        let (ix, iy) = (floor(x), floor(y));
        let (dx, dy) = (x - ix as f64, y - iy as f64);
        let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
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
}
