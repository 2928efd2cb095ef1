//! A network's parameters under PyTorch's names and layouts: the names of
//! the PyTorch twin's `state_dict` (bench-anchors/torch-repr/bench.py,
//! `Full`), so that `model.load_state_dict(safetensors.torch.load_file(f))`
//! loads our weights. `learner repr export` writes them
//! ([`crate::interop::repr_export`]).
//!
//! Layouts: convolution weights are `[cout, cin, k…]` in both; a transposed
//! convolution's `[cin, cout, k, k]` in both; a linear layer's weight is
//! burn's `[in, out]` transposed to PyTorch's `[out, in]`. Flattening an
//! image encoder's last map is channels-first in both, so the fully
//! connected rows need no permutation.
//!
//! Parts the twin has no module for keep the same scheme under their own
//! prefix: `concat_fusion.layers.{i}` (the deterministic model), `recon.*`
//! (the reconstruction model).

use super::encoders::LeakyMlp;
use super::net::ReprNet;
use burn::module::Param;
use burn::nn::Linear;
use burn::nn::conv::{Conv1d, Conv2d, ConvTranspose2d};
use burn::prelude::*;

/// One parameter: its PyTorch name, shape and values (row-major).
#[derive(Debug, Clone, PartialEq)]
pub struct NamedTensor {
    /// Its name in the twin's `state_dict`.
    pub name: String,
    /// Its shape.
    pub shape: Vec<usize>,
    /// Its values, f32 as trained.
    pub values: Vec<f32>,
}

fn values<const D: usize>(p: &Param<Tensor<D>>) -> Vec<f32> {
    p.val().try_into_vec_as::<f32>().expect("an f32 tensor")
}

/// Collects tensors under a growing list.
#[derive(Default)]
struct Names(Vec<NamedTensor>);

impl Names {
    fn push<const D: usize>(&mut self, name: String, p: &Param<Tensor<D>>) {
        self.0.push(NamedTensor {
            name,
            shape: p.val().dims().to_vec(),
            values: values(p),
        });
    }

    fn bias(&mut self, prefix: &str, b: &Option<Param<Tensor<1>>>) {
        if let Some(b) = b {
            self.push(format!("{prefix}.bias"), b);
        }
    }

    fn linear(&mut self, prefix: &str, l: &Linear) {
        let [n_in, n_out] = l.weight.val().dims();
        let w = values(&l.weight);
        let mut t = vec![0.0; w.len()];
        for i in 0..n_in {
            for o in 0..n_out {
                t[o * n_in + i] = w[i * n_out + o];
            }
        }
        self.0.push(NamedTensor {
            name: format!("{prefix}.weight"),
            shape: vec![n_out, n_in],
            values: t,
        });
        self.bias(prefix, &l.bias);
    }

    fn linears(&mut self, prefix: &str, ls: &[Linear]) {
        for (i, l) in ls.iter().enumerate() {
            self.linear(&format!("{prefix}.{i}"), l);
        }
    }

    fn mlp(&mut self, prefix: &str, m: &LeakyMlp) {
        self.linears(&format!("{prefix}.layers"), &m.layers);
    }

    fn conv2d(&mut self, prefix: &str, c: &Conv2d) {
        self.push(format!("{prefix}.weight"), &c.weight);
        self.bias(prefix, &c.bias);
    }

    fn convs2d(&mut self, prefix: &str, cs: &[Conv2d]) {
        for (i, c) in cs.iter().enumerate() {
            self.conv2d(&format!("{prefix}.{i}"), c);
        }
    }

    fn conv1d(&mut self, prefix: &str, c: &Conv1d) {
        self.push(format!("{prefix}.weight"), &c.weight);
        self.bias(prefix, &c.bias);
    }

    fn up(&mut self, prefix: &str, c: &ConvTranspose2d) {
        self.push(format!("{prefix}.weight"), &c.weight);
        self.bias(prefix, &c.bias);
    }
}

/// Every parameter of `net` under the twin's names, in a fixed order
/// (encoders, fusion, decoders).
pub fn torch_named(net: &ReprNet) -> Vec<NamedTensor> {
    let mut n = Names::default();
    if let Some(e) = &net.rgb {
        n.convs2d("rgb.convs", &e.convs);
        n.linear("rgb.fc", &e.fc);
    }
    if let Some(e) = &net.depth {
        n.convs2d("depth.convs", &e.convs);
        n.linear("depth.fc", &e.fc);
    }
    if let Some(e) = &net.haptics {
        for (i, c) in e.convs.iter().enumerate() {
            n.conv1d(&format!("wrench.convs.{i}"), c);
        }
    }
    if let Some(e) = &net.proprio {
        n.mlp("proprio", &e.mlp);
    }
    if let Some(m) = &net.concat_fusion {
        n.mlp("concat_fusion", m);
    }
    if let Some(a) = &net.action {
        n.linears("act_mlp", &a.action);
        n.linears("fuse", &a.fuse);
    }
    if let Some(f) = &net.flow {
        n.conv2d("flow.entry", &f.entry);
        for (i, u) in f.ups.iter().enumerate() {
            n.up(&format!("flow.ups.{i}"), u);
        }
        n.conv2d("flow.flow", &f.flow);
        n.conv2d("flow.mask", &f.mask);
    }
    if let Some(l) = &net.contact {
        n.linear("contact", l);
    }
    if let Some(l) = &net.pairing {
        n.linear("pairing", l);
    }
    if let Some(m) = &net.ee {
        n.mlp("ee", m);
    }
    if let Some(r) = &net.recon {
        n.linear("recon.rgb_fc", &r.rgb_fc);
        n.convs2d("recon.rgb_convs", &r.rgb_convs);
        n.mlp("recon.wrench", &r.wrench);
        n.mlp("recon.proprio", &r.proprio);
    }
    n.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::ModelConfig;

    #[test]
    fn every_parameter_is_named_once_and_linear_weights_are_transposed() {
        let cfg = ModelConfig {
            latent_dim: 8,
            image_size: 64,
            ..Default::default()
        };
        let net = ReprNet::new(&cfg, &Device::flex());
        let named = torch_named(&net);
        let total: usize = named.iter().map(|t| t.values.len()).sum();
        assert_eq!(total, net.num_params());
        let mut names: Vec<_> = named.iter().map(|t| t.name.as_str()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), named.len());
        // The RGB encoder's fully connected layer: 8 channels × 1 cell in,
        // 2d out, as PyTorch's [out, in].
        let fc = named.iter().find(|t| t.name == "rgb.fc.weight").unwrap();
        assert_eq!(fc.shape, [16, 8]);
        let w = net.rgb.as_ref().unwrap().fc.weight.val();
        let burn: Vec<f32> = w.try_into_vec_as::<f32>().unwrap();
        assert_eq!(fc.values[3 * 8 + 5], burn[5 * 16 + 3]);
        let up = named
            .iter()
            .find(|t| t.name == "flow.ups.0.weight")
            .unwrap();
        assert_eq!(up.shape, [64, 64, 4, 4]);
    }
}
