//! Numbers every layer needs.

/// `x.floor() as i64`, exactly and for every `x` (NaN gives 0; beyond the
/// ends of `i64` it saturates, as the cast does), without the library call
/// `f64::floor` is on x86-64's baseline target (no SSE4.1). Cells are found
/// this way in every hot loop of the local map, the route and the
/// simulator; the call had been 4-5 % of an ERIM mission's CPU.
#[inline]
pub fn floor_i64(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x {
        i.saturating_sub(1)
    } else {
        i
    }
}

/// Distance from point `p` to the segment a–b (plane, m).
pub fn segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (abx, aby) = (b[0] - a[0], b[1] - a[1]);
    let len2 = abx * abx + aby * aby;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * abx + (p[1] - a[1]) * aby) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * abx).hypot(p[1] - a[1] - t * aby)
}

/// Whether the segments a–b and c–d cross at a point inside both (touching
/// or overlapping along a line is no crossing).
pub fn segments_cross(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let cross = |o: [f64; 2], p: [f64; 2], q: [f64; 2]| {
        (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])
    };
    let (d1, d2) = (cross(c, d, a), cross(c, d, b));
    let (d3, d4) = (cross(a, b, c), cross(a, b, d));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

/// Whether `p` lies inside the polygon whose edges are `edges` (crossing
/// number: a ray from `p` along +x crosses them an odd number of times).
pub fn crossing_number_inside(
    edges: impl Iterator<Item = ([f64; 2], [f64; 2])>,
    p: [f64; 2],
) -> bool {
    let mut inside = false;
    for (a, b) in edges {
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_i64_is_the_floor_cast_everywhere() {
        let mut cases = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            -1.000_000_1,
            2.0f64.powi(52) + 0.5,
            -(2.0f64.powi(52)) - 0.5,
            2.0f64.powi(63),
            -(2.0f64.powi(63)),
            9.3e18,
            -9.3e18,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ];
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        for _ in 0..100_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let magnitude = 10f64.powi((state % 24) as i32 - 6);
            cases.push(((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * magnitude);
        }
        for x in cases {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x:e}");
        }
    }
}
