//! A trained network's encoders and fusion as the node's plain arrays
//! ([`EncoderWeights`]): the node's CPU inference
//! ([`learner_node::repr::FastEncoder`]) runs them, and `learner policy
//! export` writes them to the encoder's weights file. This is the one place
//! that knows burn's layouts: convolution weights `[cout, cin, k…]` become
//! `[(tap, ci), cout]` rows, and an image encoder's fully connected rows go
//! from burn's channels-first flatten to channels-last.

use super::config::ModelConfig;
use super::encoders::{LEAKY_SLOPE, LeakyMlp};
use super::fusion::MIN_VARIANCE;
use super::net::ReprNet;
use burn::module::Param;
use burn::nn::conv::{Conv1d, Conv2d};
use burn::nn::{Linear, PaddingConfig1d};
use burn::prelude::*;
use learner_node::repr::FastEncoder;
use learner_node::repr::fast::{Conv, Dense, EncoderWeights, ImageEncoder, WrenchStack};

fn values<const D: usize>(p: &Param<Tensor<D>>) -> Vec<f32> {
    p.val().try_into_vec_as::<f32>().expect("an f32 tensor")
}

/// A bias as values (zeros when the layer has none).
fn bias(b: &Option<Param<Tensor<1>>>, n: usize) -> Vec<f32> {
    b.as_ref().map_or(vec![0.0; n], values)
}

/// Convolution weights `[cout, cin, taps]` (burn's layout, the kernel
/// flattened) as the product's `[(tap, ci), cout]`, rows in tap-then-channel
/// order as the channels-last im2col lays them out.
fn taps_first(src: &[f32], cout: usize, cin: usize, taps: usize) -> Vec<f32> {
    let mut w = vec![0.0; taps * cin * cout];
    for co in 0..cout {
        for ci in 0..cin {
            for t in 0..taps {
                w[(t * cin + ci) * cout + co] = src[(co * cin + ci) * taps + t];
            }
        }
    }
    w
}

/// A linear layer (burn's weights are `[in, out]` already).
fn dense(l: &Linear) -> Dense {
    let [n_in, n_out] = l.weight.val().dims();
    Dense {
        w: values(&l.weight),
        b: bias(&l.bias, n_out),
        n_in,
        n_out,
    }
}

fn layers(mlp: &LeakyMlp) -> Vec<Dense> {
    mlp.layers.iter().map(dense).collect()
}

fn conv(c: &Conv2d) -> Conv {
    let [cout, cin, _, _] = c.weight.val().dims();
    let (k, stride, pad) = learner_kernels::conv2d_geometry(c);
    Conv {
        k,
        stride,
        pad,
        cin,
        cout,
        w: taps_first(&values(&c.weight), cout, cin, k * k),
        b: bias(&c.bias, cout),
    }
}

/// Convolutions, then the fully connected layer with its rows permuted from
/// burn's channels-first flatten to channels-last.
fn image(convs: &[Conv2d], fc: &Linear, side: usize) -> ImageEncoder {
    let convs: Vec<Conv> = convs.iter().map(conv).collect();
    let last = convs.last().expect("one convolution or more");
    let o = convs.iter().fold(side, |s, c| c.out_side(s));
    let c = last.cout;
    let mut fc = dense(fc);
    assert_eq!(fc.n_in, c * o * o);
    let src = std::mem::take(&mut fc.w);
    fc.w = vec![0.0; src.len()];
    for ch in 0..c {
        for p in 0..o * o {
            let from = (ch * o * o + p) * fc.n_out;
            let to = (p * c + ch) * fc.n_out;
            fc.w[to..to + fc.n_out].copy_from_slice(&src[from..from + fc.n_out]);
        }
    }
    ImageEncoder { convs, fc }
}

/// The wrench encoder's kernel-2, stride-2 convolutions as products over
/// pairs of time steps.
fn wrench(convs: &[Conv1d]) -> WrenchStack {
    WrenchStack(
        convs
            .iter()
            .map(|c| {
                let [cout, cin, k] = c.weight.val().dims();
                assert!(k == 2 && c.stride == 2 && c.groups == 1 && c.dilation == 1);
                assert!(matches!(c.padding, PaddingConfig1d::Valid));
                Dense {
                    w: taps_first(&values(&c.weight), cout, cin, k),
                    b: bias(&c.bias, cout),
                    n_in: k * cin,
                    n_out: cout,
                }
            })
            .collect(),
    )
}

/// The node's arrays of `net` (built for `cfg`).
pub fn encoder_weights(net: &ReprNet, cfg: &ModelConfig) -> EncoderWeights {
    let side = cfg.image_size;
    EncoderWeights {
        latent_dim: cfg.latent_dim,
        image_side: side,
        leaky_slope: LEAKY_SLOPE as f32,
        min_variance: MIN_VARIANCE as f32,
        rgb: net.rgb.as_ref().map(|e| image(&e.convs, &e.fc, side)),
        depth: net.depth.as_ref().map(|e| image(&e.convs, &e.fc, side)),
        haptics: net.haptics.as_ref().map(|e| wrench(&e.convs)),
        proprio: net.proprio.as_ref().map(|e| layers(&e.mlp)),
        concat: net.concat_fusion.as_ref().map(layers),
    }
}

/// The node's CPU inference of `net`: what `Encoder` runs on the CPU.
pub fn fast_encoder(net: &ReprNet, cfg: &ModelConfig) -> FastEncoder {
    FastEncoder::new(encoder_weights(net, cfg)).expect("a network's own layers fit each other")
}
