//! D* Lite (Koenig & Likhachev, "D* Lite", AAAI 2002; the optimised
//! version of their Figure 4) on an 8-connected grid.
//!
//! The search runs backwards, from the goal to the vehicle, so that when
//! the vehicle moves only the heuristic's offset changes (`km += h(last,
//! start)`), and when cells change only the vertices whose `rhs` they touch
//! are re-examined: a re-plan expands the part of the search the change
//! affects, not the whole grid. With `g` the cost-to-goal estimate and
//! `rhs(s) = min_{s' ∈ succ(s)} (c(s, s') + g(s'))`, a vertex is
//! inconsistent when `g ≠ rhs` and waits in the queue under the key
//!
//! ```text
//! k(s) = [min(g(s), rhs(s)) + h(start, s) + km ; min(g(s), rhs(s))]
//! ```
//!
//! The queue is a binary heap with lazy deletion: an entry whose key is no
//! longer the vertex's current one is skipped when it surfaces.
//!
//! Edges join a cell to its 8 neighbours; an edge costs its length times
//! the mean of its two cells' costs (`f32::INFINITY`: impassable), and a
//! diagonal may not cut the corner of an impassable cell. The heuristic is
//! the octile distance times the lowest cell cost, so it never
//! overestimates.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

const INF: f32 = f32::INFINITY;
const SQRT_2: f32 = std::f32::consts::SQRT_2;
/// Neighbour offsets (dx, dy): the 4 straight ones first.
const OFFSETS: [(i32, i32); 8] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (1, -1),
    (-1, 1),
    (-1, -1),
];

/// A queue entry.
#[derive(Debug, Clone, Copy)]
struct Entry {
    key: (f32, f32),
    node: u32,
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Entry {}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Entry {
    /// Reversed, so the heap's top is the smallest key.
    fn cmp(&self, other: &Self) -> Ordering {
        compare(other.key, self.key).then(other.node.cmp(&self.node))
    }
}

fn compare(a: (f32, f32), b: (f32, f32)) -> Ordering {
    a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1))
}

/// Counters of the planner's work.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PlannerStats {
    /// Plans from scratch (new goal, new area).
    pub plans: u64,
    /// Incremental re-plans after cells changed.
    pub replans: u64,
    /// Vertices expanded, in all.
    pub expansions: u64,
}

/// D* Lite over a square grid of `side × side` cells whose costs the
/// caller owns (row-major, `y · side + x`).
#[derive(Debug, Clone)]
pub struct DStarLite {
    side: usize,
    g: Vec<f32>,
    rhs: Vec<f32>,
    /// The key a queued vertex is queued under; `None` if not queued.
    queued: Vec<Option<(f32, f32)>>,
    heap: BinaryHeap<Entry>,
    start: usize,
    last: usize,
    goal: usize,
    km: f32,
    /// Lowest cell cost (scales the heuristic).
    min_cost: f32,
    /// Scratch for de-duplicating cells to re-examine.
    marks: Vec<u32>,
    mark: u32,
    pub stats: PlannerStats,
}

impl DStarLite {
    /// A planner for a `side × side` grid whose cells cost at least
    /// `min_cost` each.
    pub fn new(side: usize, min_cost: f32) -> Self {
        let n = side * side;
        Self {
            side,
            g: vec![INF; n],
            rhs: vec![INF; n],
            queued: vec![None; n],
            heap: BinaryHeap::new(),
            start: 0,
            last: 0,
            goal: 0,
            km: 0.0,
            min_cost,
            marks: vec![0; n],
            mark: 0,
            stats: PlannerStats::default(),
        }
    }

    pub fn goal(&self) -> usize {
        self.goal
    }

    pub fn start(&self) -> usize {
        self.start
    }

    /// Forgets the search: plans from `start` to `goal` from scratch at the
    /// next [`DStarLite::plan`].
    pub fn reset(&mut self, start: usize, goal: usize) {
        self.g.fill(INF);
        self.rhs.fill(INF);
        self.queued.fill(None);
        self.heap.clear();
        self.start = start;
        self.last = start;
        self.goal = goal;
        self.km = 0.0;
        self.rhs[goal] = 0.0;
        self.push(goal);
        self.stats.plans += 1;
    }

    /// The vehicle is now in cell `start`.
    pub fn move_start(&mut self, start: usize) {
        if start != self.start {
            self.km += self.heuristic(self.last, start);
            self.last = start;
            self.start = start;
        }
    }

    /// The costs of `cells` changed: every vertex whose edges they touch
    /// (the cells and their neighbours, for the corner rule) is re-examined.
    pub fn cells_changed(&mut self, costs: &[f32], cells: &[usize]) {
        if cells.is_empty() {
            return;
        }
        self.stats.replans += 1;
        self.mark = self.mark.wrapping_add(1);
        if self.mark == 0 {
            self.marks.fill(0);
            self.mark = 1;
        }
        for &cell in cells {
            for u in std::iter::once(cell).chain(self.neighbours(cell)) {
                if self.marks[u] == self.mark {
                    continue;
                }
                self.marks[u] = self.mark;
                if u != self.goal {
                    self.rhs[u] = self.best_successor(costs, u).1;
                }
                self.update_vertex(u);
            }
        }
    }

    /// Brings the search up to date; true when a path from start to goal
    /// exists. Expands at most `max_expansions` vertices.
    pub fn plan(&mut self, costs: &[f32], max_expansions: u64) -> bool {
        let mut expansions = 0;
        while let Some(top) = self.top() {
            let start_key = self.key(self.start);
            let start_consistent = self.rhs[self.start] <= self.g[self.start];
            if compare(top.key, start_key) != Ordering::Less && start_consistent {
                break;
            }
            if expansions >= max_expansions {
                break;
            }
            expansions += 1;
            let u = top.node as usize;
            let new_key = self.key(u);
            if compare(top.key, new_key) == Ordering::Less {
                self.heap.pop();
                self.push(u);
            } else if self.g[u] > self.rhs[u] {
                self.heap.pop();
                self.queued[u] = None;
                self.g[u] = self.rhs[u];
                for s in self.neighbours(u) {
                    if s != self.goal {
                        let through = self.edge(costs, s, u) + self.g[u];
                        if through < self.rhs[s] {
                            self.rhs[s] = through;
                        }
                    }
                    self.update_vertex(s);
                }
            } else {
                let g_old = self.g[u];
                self.g[u] = INF;
                for s in self.neighbours(u).chain(std::iter::once(u)) {
                    if s != self.goal && (s == u || self.rhs[s] == self.edge(costs, s, u) + g_old) {
                        self.rhs[s] = self.best_successor(costs, s).1;
                    }
                    self.update_vertex(s);
                }
            }
        }
        self.stats.expansions += expansions;
        self.g[self.start].is_finite() || self.rhs[self.start].is_finite()
    }

    /// Cost from `cell` to the goal along the current plan (∞: no path).
    pub fn cost_to_goal(&self, cell: usize) -> f32 {
        self.rhs[cell].min(self.g[cell])
    }

    /// What driving along `cells` costs at today's `costs`: the sum of the
    /// edges between consecutive cells, as the plan counts them (∞ where
    /// one is impassable, a diagonal cuts an impassable corner, or two
    /// cells are not neighbours).
    pub fn path_cost(&self, costs: &[f32], cells: &[usize]) -> f32 {
        cells
            .windows(2)
            .map(|pair| {
                let ((ux, uy), (vx, vy)) = (self.xy(pair[0]), self.xy(pair[1]));
                if (ux - vx).abs().max((uy - vy).abs()) == 1 {
                    self.edge(costs, pair[0], pair[1])
                } else {
                    INF
                }
            })
            .sum()
    }

    /// Octile distance between two cells, in cells (what crossing from one
    /// to the other costs at the least, on free ground).
    pub fn octile(&self, u: usize, v: usize) -> f32 {
        let ((ux, uy), (vx, vy)) = (self.xy(u), self.xy(v));
        let (dx, dy) = ((ux - vx).abs() as f32, (uy - vy).abs() as f32);
        dx.max(dy) + (SQRT_2 - 1.0) * dx.min(dy)
    }

    /// The cells of the plan from the start, at most `max_cells` of them
    /// after the start, into `path` (cleared first).
    pub fn path(&self, costs: &[f32], max_cells: usize, path: &mut Vec<usize>) {
        path.clear();
        let mut at = self.start;
        while at != self.goal && path.len() < max_cells {
            let (next, cost) = self.best_successor(costs, at);
            if !cost.is_finite() || path.contains(&next) {
                break;
            }
            path.push(next);
            at = next;
        }
    }

    /// The successor minimising c(u, s') + g(s'), and that sum.
    fn best_successor(&self, costs: &[f32], u: usize) -> (usize, f32) {
        let mut best = (u, INF);
        for s in self.neighbours(u) {
            let through = self.edge(costs, u, s) + self.g[s];
            if through < best.1 {
                best = (s, through);
            }
        }
        best
    }

    /// The top of the queue, dropping stale entries.
    fn top(&mut self) -> Option<Entry> {
        while let Some(&top) = self.heap.peek() {
            if self.queued[top.node as usize] == Some(top.key) {
                return Some(top);
            }
            self.heap.pop();
        }
        None
    }

    fn push(&mut self, u: usize) {
        let key = self.key(u);
        self.queued[u] = Some(key);
        self.heap.push(Entry {
            key,
            node: u as u32,
        });
        // Stale entries pile up under lazy deletion: rebuild now and then.
        if self.heap.len() > 4 * self.side * self.side + 1024 {
            let queued = &self.queued;
            let live: Vec<Entry> = self
                .heap
                .drain()
                .filter(|e| queued[e.node as usize] == Some(e.key))
                .collect();
            self.heap = live.into();
        }
    }

    fn update_vertex(&mut self, u: usize) {
        if self.g[u] != self.rhs[u] {
            if self.queued[u] != Some(self.key(u)) {
                self.push(u);
            }
        } else {
            self.queued[u] = None;
        }
    }

    fn key(&self, u: usize) -> (f32, f32) {
        let m = self.g[u].min(self.rhs[u]);
        (m + self.heuristic(self.start, u) + self.km, m)
    }

    fn xy(&self, u: usize) -> (i32, i32) {
        ((u % self.side) as i32, (u / self.side) as i32)
    }

    /// Octile distance times the lowest cell cost.
    fn heuristic(&self, a: usize, b: usize) -> f32 {
        self.octile(a, b) * self.min_cost
    }

    fn neighbours(&self, u: usize) -> impl Iterator<Item = usize> + use<> {
        let (x, y) = self.xy(u);
        let side = self.side as i32;
        OFFSETS.into_iter().filter_map(move |(dx, dy)| {
            let (nx, ny) = (x + dx, y + dy);
            ((0..side).contains(&nx) && (0..side).contains(&ny)).then(|| (ny * side + nx) as usize)
        })
    }

    /// The cost of the edge between neighbours `u` and `v`.
    fn edge(&self, costs: &[f32], u: usize, v: usize) -> f32 {
        let (cu, cv) = (costs[u], costs[v]);
        if !(cu.is_finite() && cv.is_finite()) {
            return INF;
        }
        let ((ux, uy), (vx, vy)) = (self.xy(u), self.xy(v));
        if ux != vx && uy != vy {
            // A diagonal: both cells it passes between must be passable.
            let side = self.side as i32;
            let (a, b) = ((uy * side + vx) as usize, (vy * side + ux) as usize);
            if !(costs[a].is_finite() && costs[b].is_finite()) {
                return INF;
            }
            SQRT_2 * 0.5 * (cu + cv)
        } else {
            0.5 * (cu + cv)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIDE: usize = 40;

    fn at(x: usize, y: usize) -> usize {
        y * SIDE + x
    }

    /// The cost of the cheapest path from scratch (Dijkstra), to check the
    /// incremental search against.
    fn dijkstra(planner: &DStarLite, costs: &[f32], from: usize, to: usize) -> f32 {
        let mut dist = vec![INF; SIDE * SIDE];
        let mut heap = BinaryHeap::new();
        dist[to] = 0.0;
        heap.push(Entry {
            key: (0.0, 0.0),
            node: to as u32,
        });
        while let Some(Entry { key, node }) = heap.pop() {
            let u = node as usize;
            if key.0 > dist[u] {
                continue;
            }
            for v in planner.neighbours(u) {
                let d = key.0 + planner.edge(costs, v, u);
                if d < dist[v] {
                    dist[v] = d;
                    heap.push(Entry {
                        key: (d, 0.0),
                        node: v as u32,
                    });
                }
            }
        }
        dist[from]
    }

    /// A U open to the west around x 15..=25, y 10..=30.
    fn u_shape(costs: &mut [f32]) {
        for y in 10..=30 {
            costs[at(25, y)] = INF;
        }
        for x in 15..=25 {
            costs[at(x, 10)] = INF;
            costs[at(x, 30)] = INF;
        }
    }

    #[test]
    fn it_finds_the_cheapest_path_around_a_u_and_re_plans_when_cells_close_it() {
        let mut costs = vec![1.0; SIDE * SIDE];
        u_shape(&mut costs);
        let mut planner = DStarLite::new(SIDE, 1.0);
        // From inside the U to a goal behind its closed end.
        let (start, goal) = (at(20, 20), at(35, 20));
        planner.reset(start, goal);
        assert!(planner.plan(&costs, u64::MAX));
        let cost = planner.cost_to_goal(start);
        assert!((cost - dijkstra(&planner, &costs, start, goal)).abs() < 1e-3);
        // Out of the open end and round a corner of the U: far longer
        // than the 15 m straight line.
        assert!(cost > 30.0, "{cost}");
        let mut path = Vec::new();
        planner.path(&costs, usize::MAX, &mut path);
        assert_eq!(*path.last().unwrap(), goal);
        assert!(path.iter().all(|&c| costs[c].is_finite()));
        assert!(
            path.iter().any(|&c| c % SIDE < 15),
            "leaves through the open end"
        );
        // The vehicle moves two cells towards the open end; a wall closes
        // the north side outside the U: the search repairs itself and
        // agrees with a search from scratch, expanding far fewer vertices.
        let from_scratch = planner.stats.expansions;
        planner.move_start(at(18, 20));
        let wall: Vec<usize> = (31..SIDE).map(|y| at(22, y)).collect();
        for &c in &wall {
            costs[c] = INF;
        }
        planner.cells_changed(&costs, &wall);
        assert!(planner.plan(&costs, u64::MAX));
        let repaired = planner.cost_to_goal(at(18, 20));
        let expected = dijkstra(&planner, &costs, at(18, 20), goal);
        assert!(
            (repaired - expected).abs() < 1e-3,
            "{repaired} vs {expected}"
        );
        planner.path(&costs, usize::MAX, &mut path);
        assert!(
            path.iter().all(|&c| c / SIDE <= 30) && path.iter().any(|&c| c / SIDE < 10),
            "now round the south: {path:?}"
        );
        let incremental = planner.stats.expansions - from_scratch;
        assert!(
            incremental < from_scratch,
            "{incremental} vs {from_scratch}"
        );
        assert_eq!(planner.stats.replans, 1);
    }

    #[test]
    fn a_goal_walled_off_has_no_path_until_the_wall_opens() {
        let mut costs = vec![1.0; SIDE * SIDE];
        // A closed box around the goal.
        for i in 25..=35 {
            for c in [at(i, 15), at(i, 25), at(25, i - 10), at(35, i - 10)] {
                costs[c] = INF;
            }
        }
        let mut planner = DStarLite::new(SIDE, 1.0);
        let (start, goal) = (at(5, 5), at(30, 20));
        planner.reset(start, goal);
        assert!(!planner.plan(&costs, u64::MAX));
        assert!(!planner.cost_to_goal(start).is_finite());
        // The corner cell opened leaves only a diagonal step into the box,
        // between two wall cells: no corner cutting, still no path.
        costs[at(25, 15)] = 1.0;
        planner.cells_changed(&costs, &[at(25, 15)]);
        assert!(!planner.plan(&costs, u64::MAX));
        // A gap in a side opens it.
        costs[at(25, 15)] = INF;
        costs[at(25, 20)] = 1.0;
        planner.cells_changed(&costs, &[at(25, 15), at(25, 20)]);
        assert!(planner.plan(&costs, u64::MAX));
        let expected = dijkstra(&planner, &costs, start, goal);
        assert!((planner.cost_to_goal(start) - expected).abs() < 1e-3);
    }

    #[test]
    fn dearer_cells_are_avoided_when_a_detour_is_cheap() {
        // A band of unseen ground (cost 2) across the straight line, with a
        // seen gap (cost 1) two cells aside.
        let mut costs = vec![1.0; SIDE * SIDE];
        for y in 0..SIDE {
            if y != 22 {
                for x in 18..=21 {
                    costs[at(x, y)] = 2.0;
                }
            }
        }
        let mut planner = DStarLite::new(SIDE, 1.0);
        planner.reset(at(5, 20), at(35, 20));
        assert!(planner.plan(&costs, u64::MAX));
        let mut path = Vec::new();
        planner.path(&costs, usize::MAX, &mut path);
        assert!(path.contains(&at(19, 22)), "through the gap: {path:?}");
    }
}
