//! Running mean and variance of observations (rsl_rl's empirical normalization),
//! saved with the checkpoint: `(x - mean) / (std + eps)`, clipped.
use tch::Tensor;

/// Per-dimension running statistics over `dim`-float rows.
#[derive(Debug, Clone, PartialEq)]
pub struct RunningNorm {
    pub dim: usize,
    pub mean: Vec<f64>,
    pub var: Vec<f64>,
    pub count: f64,
    /// Normalized values are clipped to +-clip.
    pub clip: f32,
    /// Frozen statistics are applied but not updated (evaluation).
    pub frozen: bool,
    scale: Vec<f32>,
    shift: Vec<f32>,
}

const EPS: f64 = 1e-2;

impl RunningNorm {
    pub fn new(dim: usize) -> RunningNorm {
        let mut n = RunningNorm {
            dim,
            mean: vec![0.0; dim],
            var: vec![1.0; dim],
            count: 0.0,
            clip: 5.0,
            frozen: false,
            scale: vec![1.0; dim],
            shift: vec![0.0; dim],
        };
        n.refresh();
        n
    }

    fn refresh(&mut self) {
        for i in 0..self.dim {
            let s = 1.0 / (self.var[i].sqrt() + EPS);
            self.scale[i] = s as f32;
            self.shift[i] = (-self.mean[i] * s) as f32;
        }
    }

    /// Add a batch of rows (Chan et al.'s parallel update).
    pub fn update(&mut self, rows: &[f32]) {
        if self.frozen || self.dim == 0 || rows.is_empty() {
            return;
        }
        let n = (rows.len() / self.dim) as f64;
        let mut bmean = vec![0.0; self.dim];
        for r in rows.chunks_exact(self.dim) {
            for (m, &x) in bmean.iter_mut().zip(r) {
                *m += x as f64;
            }
        }
        bmean.iter_mut().for_each(|m| *m /= n);
        let mut bvar = vec![0.0; self.dim];
        for r in rows.chunks_exact(self.dim) {
            for ((v, &x), m) in bvar.iter_mut().zip(r).zip(&bmean) {
                *v += (x as f64 - m).powi(2);
            }
        }
        bvar.iter_mut().for_each(|v| *v /= n);
        let total = self.count + n;
        for i in 0..self.dim {
            let delta = bmean[i] - self.mean[i];
            let m2 =
                self.var[i] * self.count + bvar[i] * n + delta * delta * self.count * n / total;
            self.mean[i] += delta * n / total;
            self.var[i] = m2 / total;
        }
        self.count = total;
        self.refresh();
    }

    /// Normalize one row into `out`.
    #[inline]
    pub fn apply(&self, row: &[f32], out: &mut [f32]) {
        let c = self.clip;
        for i in 0..self.dim {
            out[i] = (row[i] * self.scale[i] + self.shift[i]).clamp(-c, c);
        }
    }

    /// `(mean, std + eps)` as f32 tensors, for exporting the normalization.
    pub fn tensors(&self) -> (Tensor, Tensor) {
        let mean: Vec<f32> = self.mean.iter().map(|&m| m as f32).collect();
        let std: Vec<f32> = self.var.iter().map(|&v| (v.sqrt() + EPS) as f32).collect();
        (Tensor::from_slice(&mean), Tensor::from_slice(&std))
    }

    /// State for a checkpoint: mean, var, then count.
    pub fn to_vec(&self) -> Vec<f64> {
        let mut v = self.mean.clone();
        v.extend(&self.var);
        v.push(self.count);
        v
    }

    /// Inverse of [`RunningNorm::to_vec`]; None if the length does not match.
    pub fn from_vec(dim: usize, v: &[f64]) -> Option<RunningNorm> {
        if v.len() != 2 * dim + 1 {
            return None;
        }
        let mut n = RunningNorm::new(dim);
        n.mean.copy_from_slice(&v[..dim]);
        n.var.copy_from_slice(&v[dim..2 * dim]);
        n.count = v[2 * dim];
        n.refresh();
        Some(n)
    }
}
