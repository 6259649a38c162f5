//! Point subsampling to N points: uniform, and stochastic farthest-point sampling.

use nalgebra::Vector3;

/// Keep at most `n` indices spread uniformly over `0..len` (every len/n-th, deterministic).
pub fn subsample_uniform(len: usize, n: usize, out: &mut Vec<usize>) {
    out.clear();
    if n == 0 || len == 0 {
        return;
    }
    if len <= n {
        out.extend(0..len);
        return;
    }
    out.extend((0..n).map(|k| k * len / n));
}

/// Stochastic farthest-point sampling (Taylor et al. 2016 §3.4, after Mitchell 1991): each new
/// sample is the farthest, from the current sample set, of `candidates` random points (5 in the
/// paper). Nearest-sample distances come from a uniform 3D grid over the points' bounding box, so
/// a step costs a few cell visits instead of a scan of the set. Reproducible from `seed`;
/// buffers are reused between calls.
#[derive(Clone, Debug, Default)]
pub struct FarthestSampler {
    head: Vec<u32>,
    next: Vec<u32>,
    taken: Vec<bool>,
    dims: [usize; 3],
    origin: Vector3<f64>,
    cell: f64,
}

const NIL: u32 = u32::MAX;

impl FarthestSampler {
    fn cell_of(&self, p: &Vector3<f64>) -> [usize; 3] {
        let mut c = [0usize; 3];
        for k in 0..3 {
            let x = ((p[k] - self.origin[k]) / self.cell).floor().max(0.0) as usize;
            c[k] = x.min(self.dims[k] - 1);
        }
        c
    }

    fn nearest_sq(&self, points: &[Vector3<f64>], p: &Vector3<f64>) -> f64 {
        let c = self.cell_of(p);
        let mut best = f64::INFINITY;
        let max_ring = self.dims.iter().copied().max().unwrap_or(1);
        for ring in 0..max_ring {
            // Every point outside ring `ring` is at least (ring)·cell away.
            let bound = (ring as f64 - 1.0).max(0.0) * self.cell;
            if bound * bound > best {
                break;
            }
            let lo = |k: usize| c[k].saturating_sub(ring);
            let hi = |k: usize| (c[k] + ring).min(self.dims[k] - 1);
            for x in lo(0)..=hi(0) {
                for y in lo(1)..=hi(1) {
                    for z in lo(2)..=hi(2) {
                        let on_shell = x.abs_diff(c[0]) == ring
                            || y.abs_diff(c[1]) == ring
                            || z.abs_diff(c[2]) == ring;
                        if !on_shell {
                            continue;
                        }
                        let mut i = self.head[(x * self.dims[1] + y) * self.dims[2] + z];
                        while i != NIL {
                            best = best.min((points[i as usize] - p).norm_squared());
                            i = self.next[i as usize];
                        }
                    }
                }
            }
        }
        best
    }

    /// Sample at most `n` indices of `points` into `out`.
    pub fn sample(
        &mut self,
        points: &[Vector3<f64>],
        n: usize,
        candidates: usize,
        seed: u64,
        out: &mut Vec<usize>,
    ) {
        out.clear();
        let len = points.len();
        if n == 0 || len == 0 {
            return;
        }
        if len <= n {
            out.extend(0..len);
            return;
        }
        let (mut lo, mut hi) = (points[0], points[0]);
        for p in points {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let ext = hi - lo;
        let vol = (ext.x.max(1.0)) * (ext.y.max(1.0)) * (ext.z.max(1.0));
        self.cell = (vol / n as f64).cbrt().max(1e-3);
        for k in 0..3 {
            self.dims[k] = ((ext[k] / self.cell).floor() as usize + 1).clamp(1, 64);
        }
        self.origin = lo;
        self.head.clear();
        self.head
            .resize(self.dims[0] * self.dims[1] * self.dims[2], NIL);
        self.next.clear();
        self.next.resize(len, NIL);
        self.taken.clear();
        self.taken.resize(len, false);
        let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut rand = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % len as u64) as usize
        };
        let mut pick = rand();
        while out.len() < n {
            out.push(pick);
            self.taken[pick] = true;
            let c = self.cell_of(&points[pick]);
            let h = (c[0] * self.dims[1] + c[1]) * self.dims[2] + c[2];
            self.next[pick] = self.head[h];
            self.head[h] = pick as u32;
            let mut best = usize::MAX;
            let mut best_d = -1.0;
            for _ in 0..candidates.max(1) {
                let cand = rand();
                if self.taken[cand] {
                    continue;
                }
                let d = self.nearest_sq(points, &points[cand]);
                if d > best_d {
                    best_d = d;
                    best = cand;
                }
            }
            if best == usize::MAX {
                match self.taken.iter().position(|&t| !t) {
                    Some(i) => best = i,
                    None => break,
                }
            }
            pick = best;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn farthest_sampling_spreads_points() {
        // Two clusters, one large: farthest sampling must hit both.
        let mut pts: Vec<Vector3<f64>> = (0..1000)
            .map(|i| Vector3::new((i % 10) as f64 * 0.1, (i / 10) as f64 * 0.1, 0.0))
            .collect();
        pts.extend((0..10).map(|i| Vector3::new(100.0 + i as f64, 0.0, 0.0)));
        let mut out = Vec::new();
        FarthestSampler::default().sample(&pts, 50, 5, 1, &mut out);
        assert_eq!(out.len(), 50);
        let mut u = out.clone();
        u.sort_unstable();
        u.dedup();
        assert_eq!(u.len(), 50, "duplicates");
        let mut uni = Vec::new();
        subsample_uniform(1010, 50, &mut uni);
        assert_eq!(uni.len(), 50);
        assert!(uni.windows(2).all(|w| w[0] < w[1]));
    }
}
