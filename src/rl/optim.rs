//! Adam with its moments held as plain tensors, so that a checkpoint can save and
//! restore them (tch's optimizer keeps its state inside libtorch), plus global
//! gradient-norm clipping.
use tch::{Kind, Tensor};

/// Adam over a fixed, named list of parameters.
pub struct Adam {
    params: Vec<(String, Tensor)>,
    pub m: Vec<Tensor>,
    pub v: Vec<Tensor>,
    pub step: i64,
    pub lr: f64,
    /// A parameter's own fixed rate (`None`: `lr`); such parameters are also
    /// left out of [`Adam::clip_grad_norm`].
    fixed_lr: Vec<Option<f64>>,
    beta1: f64,
    beta2: f64,
    eps: f64,
}

impl Adam {
    pub fn new(params: Vec<(String, Tensor)>, lr: f64) -> Adam {
        let zeros = |p: &Tensor| p.zeros_like().detach();
        Adam {
            m: params.iter().map(|(_, p)| zeros(p)).collect(),
            v: params.iter().map(|(_, p)| zeros(p)).collect(),
            fixed_lr: vec![None; params.len()],
            params,
            step: 0,
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }

    /// Give the parameters whose names start with `prefix` their own fixed
    /// rate `lr` (the adaptive rate then steers the others only), and leave
    /// them out of the global gradient clipping.
    pub fn fix_lr(&mut self, prefix: &str, lr: f64) {
        for (i, (name, _)) in self.params.iter().enumerate() {
            if name.starts_with(prefix) {
                self.fixed_lr[i] = Some(lr);
            }
        }
    }

    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.params.iter().map(|(n, _)| n.as_str())
    }

    /// The moments as `adam_m.<name>` and `adam_v.<name>` (for a checkpoint).
    pub fn named_moments(&self) -> Vec<(String, Tensor)> {
        let mut out = Vec::with_capacity(2 * self.params.len());
        for (i, (name, _)) in self.params.iter().enumerate() {
            out.push((format!("adam_m.{name}"), self.m[i].shallow_clone()));
            out.push((format!("adam_v.{name}"), self.v[i].shallow_clone()));
        }
        out
    }

    /// Copy saved moments in, looked up by their [`Adam::named_moments`] names.
    pub fn load_moments<'a, E>(
        &mut self,
        mut get: impl FnMut(&str) -> Result<&'a Tensor, E>,
    ) -> Result<(), E> {
        for i in 0..self.params.len() {
            let name = self.params[i].0.clone();
            let m = get(&format!("adam_m.{name}"))?;
            let v = get(&format!("adam_v.{name}"))?;
            tch::no_grad(|| {
                self.m[i].copy_(m);
                self.v[i].copy_(v);
            });
        }
        Ok(())
    }

    pub fn zero_grad(&mut self) {
        for (_, p) in &mut self.params {
            let mut g = p.grad();
            if g.defined() {
                let _ = g.zero_();
            }
        }
    }

    /// Scale gradients so that their global L2 norm is at most `max_norm`;
    /// returns the norm before clipping.
    pub fn clip_grad_norm(&mut self, max_norm: f64) -> f64 {
        let grads: Vec<Tensor> = self
            .params
            .iter()
            .zip(&self.fixed_lr)
            .filter(|(_, f)| f.is_none())
            .map(|((_, p), _)| p.grad())
            .filter(|g| g.defined())
            .collect();
        if grads.is_empty() {
            return 0.0;
        }
        let total = tch::no_grad(|| {
            Tensor::stack(
                &grads
                    .iter()
                    .map(|g| g.square().sum(Kind::Float))
                    .collect::<Vec<_>>(),
                0,
            )
            .sum(Kind::Float)
            .sqrt()
            .double_value(&[])
        });
        if total > max_norm {
            let c = max_norm / (total + 1e-6);
            tch::no_grad(|| {
                for mut g in grads {
                    let _ = g.g_mul_scalar_(c);
                }
            });
        }
        total
    }

    /// One Adam step with the current learning rate.
    pub fn step(&mut self) {
        self.step += 1;
        let (b1, b2) = (self.beta1, self.beta2);
        let bc1 = 1.0 - b1.powi(self.step as i32);
        let bc2 = 1.0 - b2.powi(self.step as i32);
        let lr = self.lr;
        let eps = self.eps;
        tch::no_grad(|| {
            for (i, (_, p)) in self.params.iter_mut().enumerate() {
                let g = p.grad();
                if !g.defined() {
                    continue;
                }
                let _ = self.m[i].g_mul_scalar_(b1).g_add_(&(&g * (1.0 - b1)));
                let _ = self.v[i]
                    .g_mul_scalar_(b2)
                    .g_add_(&(g.square() * (1.0 - b2)));
                let denom = (&self.v[i] / bc2).sqrt() + eps;
                let update = (&self.m[i] / bc1) / denom * self.fixed_lr[i].unwrap_or(lr);
                let _ = p.g_sub_(&update);
            }
        });
    }
}
