//! Which patches of a square of the world some image observed.

/// Which patches of a square of the world some image observed: patch
/// (`i0 + c`, `j0 + r`) is bit `r·side + c` of `words`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SeenGround {
    pub i0: i64,
    pub j0: i64,
    pub side: u32,
    pub words: Vec<u64>,
}

impl SeenGround {
    /// A square of `side` patches from (`i0`, `j0`), nothing seen.
    pub fn new(i0: i64, j0: i64, side: u32) -> Self {
        Self {
            i0,
            j0,
            side,
            words: vec![0; Self::words_for(side)],
        }
    }

    /// The words a square of `side` patches takes.
    pub fn words_for(side: u32) -> usize {
        (side as usize).pow(2).div_ceil(64)
    }

    /// The patches seen, as world indices (i, j).
    pub fn iter(&self) -> impl Iterator<Item = (i64, i64)> + '_ {
        let side = i64::from(self.side);
        self.words.iter().enumerate().flat_map(move |(w, &word)| {
            std::iter::successors((word != 0).then_some(word), |&bits| {
                let rest = bits & (bits - 1);
                (rest != 0).then_some(rest)
            })
            .map(move |bits| {
                let b = w as i64 * 64 + i64::from(bits.trailing_zeros());
                (self.i0 + b % side, self.j0 + b / side)
            })
        })
    }

    pub(super) fn bit(&self, i: i64, j: i64) -> Option<usize> {
        let (c, r) = (i.checked_sub(self.i0)?, j.checked_sub(self.j0)?);
        let side = i64::from(self.side);
        ((0..side).contains(&c) && (0..side).contains(&r)).then(|| (r * side + c) as usize)
    }

    /// Whether world patch (`i`, `j`) was seen (outside the square: no).
    pub fn contains(&self, i: i64, j: i64) -> bool {
        self.bit(i, j).is_some_and(|b| {
            self.words
                .get(b / 64)
                .is_some_and(|w| w & (1 << (b % 64)) != 0)
        })
    }

    pub fn insert(&mut self, i: i64, j: i64) {
        if let Some(b) = self.bit(i, j)
            && let Some(word) = self.words.get_mut(b / 64)
        {
            *word |= 1 << (b % 64);
        }
    }

    /// Patches seen.
    pub fn count(&self) -> u32 {
        self.words.iter().map(|w| w.count_ones()).sum()
    }
}
