//! A small f64 multilayer perceptron with hand-written derivatives: the
//! gradient of a loss of its outputs with respect to its parameters
//! (reverse mode) and the product of its parameter Jacobian with a vector
//! (forward mode). TRPO needs both for its Fisher-vector products, which a
//! first-order autodiff (burn's) cannot give without grad of grad.
//!
//! Layout of the flat parameter vector: per layer the weights (row-major,
//! outputs × inputs) then the biases. Hidden layers are tanh, the output is
//! linear.

use super::adam::Adam;
use rand::seq::SliceRandom;
use stack_common::rng::{self, SimRng};

/// The network's shape; parameters are kept apart (a flat slice) so that
/// TRPO can try candidates without copying the network.
#[derive(Debug, Clone, PartialEq)]
pub struct Mlp {
    sizes: Vec<usize>,
}

/// The activations of a forward pass over a batch, kept for the
/// derivatives: `acts[0]` the inputs, `acts[l]` layer l's outputs.
#[derive(Debug, Clone, Default)]
pub struct Cache {
    acts: Vec<Vec<f64>>,
    n: usize,
}

impl Cache {
    /// The network's outputs (batch × output size).
    pub fn output(&self) -> &[f64] {
        self.acts.last().map_or(&[], |a| a.as_slice())
    }

    /// Batch size of the pass.
    pub fn len(&self) -> usize {
        self.n
    }

    /// True for an empty batch.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }
}

impl Mlp {
    /// A network with layer sizes `sizes` (input, hidden…, output).
    pub fn new(sizes: &[usize]) -> Self {
        assert!(sizes.len() >= 2 && sizes.iter().all(|&s| s > 0));
        Self {
            sizes: sizes.to_vec(),
        }
    }

    /// Layer sizes.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }

    /// Input size.
    pub fn input(&self) -> usize {
        self.sizes[0]
    }

    /// Output size.
    pub fn output(&self) -> usize {
        *self.sizes.last().expect("two sizes at least")
    }

    /// Parameters in all.
    pub fn num_params(&self) -> usize {
        self.sizes.windows(2).map(|w| w[0] * w[1] + w[1]).sum()
    }

    /// Initial parameters: weights uniform in ±1/√inputs, biases 0, the
    /// output layer's weights scaled by `output_scale` (0.1 gives a policy
    /// whose initial mean is near 0, as pytorch-trpo initialises it).
    pub fn init(&self, rng: &mut SimRng, output_scale: f64) -> Vec<f64> {
        let mut p = Vec::with_capacity(self.num_params());
        let layers = self.sizes.len() - 1;
        for (l, w) in self.sizes.windows(2).enumerate() {
            let bound = 1.0 / (w[0] as f64).sqrt();
            let scale = if l + 1 == layers { output_scale } else { 1.0 };
            for _ in 0..w[0] * w[1] {
                p.push(scale * bound * (2.0 * rng::unit(rng) - 1.0));
            }
            p.extend(std::iter::repeat_n(0.0, w[1]));
        }
        p
    }

    fn hidden(&self, l: usize) -> bool {
        l + 2 < self.sizes.len()
    }

    /// Forward pass over `n = x.len() / input` samples.
    pub fn forward(&self, params: &[f64], x: &[f64], cache: &mut Cache) {
        assert_eq!(params.len(), self.num_params());
        assert_eq!(x.len() % self.input(), 0);
        let n = x.len() / self.input();
        cache.n = n;
        cache.acts.resize(self.sizes.len(), Vec::new());
        cache.acts[0].clear();
        cache.acts[0].extend_from_slice(x);
        let mut off = 0;
        for l in 0..self.sizes.len() - 1 {
            let (i, o) = (self.sizes[l], self.sizes[l + 1]);
            let w = &params[off..off + i * o];
            let b = &params[off + i * o..off + i * o + o];
            off += i * o + o;
            let (prev, rest) = cache.acts.split_at_mut(l + 1);
            let a = &prev[l];
            let z = &mut rest[0];
            z.clear();
            z.resize(n * o, 0.0);
            for s in 0..n {
                let xin = &a[s * i..(s + 1) * i];
                for k in 0..o {
                    let row = &w[k * i..(k + 1) * i];
                    let mut acc = b[k];
                    for (wk, xk) in row.iter().zip(xin) {
                        acc += wk * xk;
                    }
                    z[s * o + k] = if self.hidden(l) { acc.tanh() } else { acc };
                }
            }
        }
    }

    /// Adds to `grad` the gradient of Σ_samples ⟨dout, output⟩ with respect
    /// to the parameters, for the pass in `cache` (reverse mode).
    pub fn backward(&self, params: &[f64], cache: &Cache, dout: &[f64], grad: &mut [f64]) {
        let n = cache.n;
        let layers = self.sizes.len() - 1;
        assert_eq!(dout.len(), n * self.output());
        assert_eq!(grad.len(), self.num_params());
        let offsets = self.offsets();
        let mut delta = dout.to_vec();
        for l in (0..layers).rev() {
            let (i, o) = (self.sizes[l], self.sizes[l + 1]);
            let off = offsets[l];
            let a = &cache.acts[l];
            {
                let (gw, gb) = grad[off..off + i * o + o].split_at_mut(i * o);
                for s in 0..n {
                    let d = &delta[s * o..(s + 1) * o];
                    let xin = &a[s * i..(s + 1) * i];
                    for k in 0..o {
                        let dk = d[k];
                        gb[k] += dk;
                        for (g, x) in gw[k * i..(k + 1) * i].iter_mut().zip(xin) {
                            *g += dk * x;
                        }
                    }
                }
            }
            if l == 0 {
                break;
            }
            // δ of the layer below: Wᵀδ through tanh' = 1 − a².
            let w = &params[off..off + i * o];
            let mut below = vec![0.0; n * i];
            for s in 0..n {
                let d = &delta[s * o..(s + 1) * o];
                let out = &mut below[s * i..(s + 1) * i];
                for k in 0..o {
                    for (b, wk) in out.iter_mut().zip(&w[k * i..(k + 1) * i]) {
                        *b += d[k] * wk;
                    }
                }
                for (b, x) in out.iter_mut().zip(&a[s * i..(s + 1) * i]) {
                    *b *= 1.0 - x * x;
                }
            }
            delta = below;
        }
    }

    /// The change of the outputs along `v` in parameter space, J·v (batch ×
    /// output), for the pass in `cache` (forward mode).
    pub fn jvp(&self, params: &[f64], cache: &Cache, v: &[f64]) -> Vec<f64> {
        assert_eq!(v.len(), self.num_params());
        let n = cache.n;
        let offsets = self.offsets();
        // Tangent of the current layer's input: zero for the data.
        let mut t = vec![0.0; n * self.input()];
        for (l, &off) in offsets.iter().enumerate() {
            let (i, o) = (self.sizes[l], self.sizes[l + 1]);
            let w = &params[off..off + i * o];
            let (vw, vb) = v[off..off + i * o + o].split_at(i * o);
            let a = &cache.acts[l];
            let out = &cache.acts[l + 1];
            let mut next = vec![0.0; n * o];
            for s in 0..n {
                let xin = &a[s * i..(s + 1) * i];
                let tin = &t[s * i..(s + 1) * i];
                for k in 0..o {
                    let mut dz = vb[k];
                    for j in 0..i {
                        dz += vw[k * i + j] * xin[j] + w[k * i + j] * tin[j];
                    }
                    next[s * o + k] = if self.hidden(l) {
                        let y = out[s * o + k];
                        (1.0 - y * y) * dz
                    } else {
                        dz
                    };
                }
            }
            t = next;
        }
        t
    }

    fn offsets(&self) -> Vec<usize> {
        let mut off = 0;
        self.sizes
            .windows(2)
            .map(|w| {
                let o = off;
                off += w[0] * w[1] + w[1];
                o
            })
            .collect()
    }
}

/// Least-squares regression of an [`Mlp`]'s outputs onto targets with Adam:
/// what the value network's fit and a distilled policy's fit share.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MseFit {
    /// Passes over the samples, each in a fresh random order.
    pub epochs: usize,
    /// Samples per Adam step.
    pub minibatch: usize,
    /// Adam's step size.
    pub learning_rate: f64,
    /// L2 penalty on every parameter.
    pub l2: f64,
}

impl MseFit {
    /// Fits `params` to the rows of `y` (batch × output) from the rows of
    /// `x` (batch × input): per minibatch one Adam step on the squared error
    /// summed over outputs and averaged over samples, plus the L2 penalty.
    pub fn run(
        &self,
        mlp: &Mlp,
        params: &mut [f64],
        adam: &mut Adam,
        x: &[f64],
        y: &[f64],
        rng: &mut SimRng,
    ) {
        let (d, k) = (mlp.input(), mlp.output());
        let n = x.len() / d;
        assert_eq!(y.len(), n * k, "one target row per input row");
        let mut order: Vec<usize> = (0..n).collect();
        let mut cache = Cache::default();
        let (mut xb, mut dout) = (Vec::new(), Vec::new());
        let mut grad = vec![0.0; params.len()];
        for _ in 0..self.epochs {
            order.shuffle(rng);
            for idx in order.chunks(self.minibatch.max(1)) {
                xb.clear();
                for &i in idx {
                    xb.extend_from_slice(&x[i * d..(i + 1) * d]);
                }
                mlp.forward(params, &xb, &mut cache);
                let m = idx.len() as f64;
                dout.clear();
                for (r, &i) in idx.iter().enumerate() {
                    for c in 0..k {
                        dout.push(-2.0 * (cache.output()[r * k + c] - y[i * k + c]) / m);
                    }
                }
                // Descent on the loss is ascent on its negative gradient.
                for (g, w) in grad.iter_mut().zip(params.iter()) {
                    *g = -2.0 * self.l2 * w;
                }
                mlp.backward(params, &cache, &dout, &mut grad);
                adam.ascend(params, &grad, self.learning_rate);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn net() -> (Mlp, Vec<f64>, Vec<f64>) {
        let m = Mlp::new(&[3, 5, 4, 2]);
        let mut rng = stack_common::rng::seeded(7, 0);
        let p = m.init(&mut rng, 1.0);
        let x: Vec<f64> = (0..9).map(|k| (k as f64 * 0.37).sin()).collect();
        (m, p, x)
    }

    /// Central differences of the outputs along a parameter direction.
    fn numeric(m: &Mlp, p: &[f64], x: &[f64], v: &[f64]) -> Vec<f64> {
        let h = 1e-6;
        let mut c = Cache::default();
        let plus: Vec<f64> = p.iter().zip(v).map(|(a, b)| a + h * b).collect();
        let minus: Vec<f64> = p.iter().zip(v).map(|(a, b)| a - h * b).collect();
        m.forward(&plus, x, &mut c);
        let yp = c.output().to_vec();
        m.forward(&minus, x, &mut c);
        yp.iter()
            .zip(c.output())
            .map(|(a, b)| (a - b) / (2.0 * h))
            .collect()
    }

    #[test]
    fn jvp_matches_finite_differences() {
        let (m, p, x) = net();
        let mut c = Cache::default();
        m.forward(&p, &x, &mut c);
        let v: Vec<f64> = (0..m.num_params()).map(|k| (k as f64).cos()).collect();
        let got = m.jvp(&p, &c, &v);
        let want = numeric(&m, &p, &x, &v);
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() < 1e-7, "{g} vs {w}");
        }
    }

    #[test]
    fn backward_is_the_transpose_of_jvp() {
        // ⟨u, J v⟩ = ⟨Jᵀ u, v⟩ for any u, v.
        let (m, p, x) = net();
        let mut c = Cache::default();
        m.forward(&p, &x, &mut c);
        let v: Vec<f64> = (0..m.num_params())
            .map(|k| (k as f64 * 0.7).sin())
            .collect();
        let u: Vec<f64> = (0..6).map(|k| 1.0 - 0.3 * k as f64).collect();
        let jv = m.jvp(&p, &c, &v);
        let mut jtu = vec![0.0; m.num_params()];
        m.backward(&p, &c, &u, &mut jtu);
        let lhs: f64 = u.iter().zip(&jv).map(|(a, b)| a * b).sum();
        let rhs: f64 = jtu.iter().zip(&v).map(|(a, b)| a * b).sum();
        assert!(
            (lhs - rhs).abs() < 1e-10 * lhs.abs().max(1.0),
            "{lhs} {rhs}"
        );
        // And the gradient of one output against finite differences.
        let e0: Vec<f64> = (0..m.num_params()).map(|k| (k == 3) as u8 as f64).collect();
        let d = numeric(&m, &p, &x, &e0);
        let want: f64 = d.iter().zip(&u).map(|(a, b)| a * b).sum();
        assert!((jtu[3] - want).abs() < 1e-7);
    }
}
