//! The decoders (paper, "Self-Supervised Predictions and Decoder
//! Architecture" and "Reconstruction Model"): the action-conditional
//! feature, the optical flow and mask decoder with skip connections, and the
//! reconstruction model's decoders.

use super::encoders::{IMAGE_DOWNSAMPLE, LeakyMlp, RGB_CHANNELS, act};
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{Linear, LinearConfig, PaddingConfig2d};
use burn::prelude::*;
use burn::tensor::activation::sigmoid;
use learner_kernels::{conv_transpose2d, conv2d};

/// Width of the action encoding.
const ACTION_FEATURES: usize = 32;

/// The action-conditional feature: the next action through a two-layer MLP,
/// concatenated with z, through a two-layer MLP (both with leaky ReLU after
/// every layer, as the authors' code).
#[derive(Module, Debug)]
pub struct ActionFusion {
    pub(crate) action: Vec<Linear>,
    pub(crate) fuse: Vec<Linear>,
}

impl ActionFusion {
    /// For latent size `d` and actions of 4 values.
    pub fn new(d: usize, device: &Device) -> Self {
        Self {
            action: vec![
                LinearConfig::new(4, ACTION_FEATURES).init(device),
                LinearConfig::new(ACTION_FEATURES, ACTION_FEATURES).init(device),
            ],
            fuse: vec![
                LinearConfig::new(d + ACTION_FEATURES, 128).init(device),
                LinearConfig::new(128, d).init(device),
            ],
        }
    }

    /// (`z` `[B, d]`, the action `[B, 4]`) → `[B, d]`.
    pub fn forward(&self, z: Tensor<2>, action: Tensor<2>) -> Tensor<2> {
        let mut a = action;
        for l in &self.action {
            a = act(l.forward(a));
        }
        let mut h = Tensor::cat(vec![z, a], 1);
        for l in &self.fuse {
            h = act(l.forward(h));
        }
        h
    }
}

fn conv3(cin: usize, cout: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([cin, cout], [3, 3])
        .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
        .init(device)
}

fn up(cin: usize, cout: usize, device: &Device) -> ConvTranspose2d {
    // Kernel 4, stride 2, padding 1: exactly doubles the side.
    ConvTranspose2dConfig::new([cin, cout], [4, 4])
        .with_stride([2, 2])
        .with_padding([1, 1])
        .init(device)
}

/// `a` and `b` joined along the channels: [`learner_kernels::cat_channels`],
/// one operation with its own backward pass (burn's `cat` under
/// `KernelChoice::Burn`).
fn join(a: Tensor<4>, b: Tensor<4>) -> Tensor<4> {
    learner_kernels::cat_channels(a, b)
}

/// Bilinear upsampling by `factor` with aligned corners:
/// [`learner_kernels::upsample_bilinear`], one operation with its own
/// backward pass (on the GPU backends two products with constant
/// interpolation matrices: burn's GPU backends have no backward pass for
/// `interpolate`). The same map as `interpolate(.., Bilinear,
/// align_corners)`, tested against it.
fn upsample(x: Tensor<4>, factor: usize) -> Tensor<4> {
    learner_kernels::upsample_bilinear(x, factor)
}

/// Channels of the up-convolutions, coarsest first.
const FLOW_UP: [usize; 4] = [64, 32, 32, 32];

/// The flow decoder: the action-conditional feature tiled over the RGB
/// encoder's coarsest map, a 1×1 convolution, then four up-convolutions,
/// each followed by the RGB encoder's map of its size (four skip
/// connections, FlowNet's refinement). At side S/4 one convolution predicts
/// the unmasked flow, another the mask; their product (mask through a
/// sigmoid) is the robot's flow, upsampled ×4 to the image.
#[derive(Module, Debug)]
pub struct FlowDecoder {
    pub(crate) entry: Conv2d,
    pub(crate) ups: Vec<ConvTranspose2d>,
    pub(crate) flow: Conv2d,
    pub(crate) mask: Conv2d,
}

/// The flow decoder's prediction at full size.
#[derive(Debug, Clone)]
pub struct FlowPrediction {
    /// Masked flow, px, `[B, 2, S, S]`.
    pub flow: Tensor<4>,
    /// Mask logits, `[B, 1, S, S]`.
    pub mask_logits: Tensor<4>,
}

impl FlowDecoder {
    /// For latent size `d`.
    pub fn new(d: usize, device: &Device) -> Self {
        // Skip maps joined after each up-convolution: the RGB encoder's
        // layers 5, 4, 3, 2 (sides S/32 … S/4).
        let skips = [
            RGB_CHANNELS[4],
            RGB_CHANNELS[3],
            RGB_CHANNELS[2],
            RGB_CHANNELS[1],
        ];
        let entry = Conv2dConfig::new([2 * d, FLOW_UP[0]], [1, 1]).init(device);
        let mut ups = Vec::new();
        let mut cin = FLOW_UP[0];
        for (i, &cout) in FLOW_UP.iter().enumerate() {
            ups.push(up(cin, cout, device));
            cin = cout + skips[i];
        }
        Self {
            entry,
            ups,
            flow: conv3(cin, 2, device),
            mask: conv3(cin, 1, device),
        }
    }

    /// `feature` `[B, d]` and the RGB encoder's six maps (finest first)
    /// → the prediction.
    pub fn forward(&self, feature: Tensor<2>, maps: &[Tensor<4>]) -> FlowPrediction {
        let coarsest = &maps[5];
        let [b, d, s, _] = coarsest.dims();
        let tiled = feature.reshape([b, d, 1, 1]).expand([b, d, s, s]);
        let mut x = act(conv2d(&self.entry, join(coarsest.clone(), tiled)));
        for (i, u) in self.ups.iter().enumerate() {
            x = act(conv_transpose2d(u, x));
            x = join(x, maps[4 - i].clone());
        }
        let mask_logits = conv2d(&self.mask, x.clone());
        let flow = conv2d(&self.flow, x) * sigmoid(mask_logits.clone());
        FlowPrediction {
            flow: upsample(flow, 4),
            mask_logits: upsample(mask_logits, 4),
        }
    }
}

/// Zero feature maps shaped like the RGB encoder's, for a model whose RGB
/// input is masked: the flow decoder then works from z alone.
pub fn zero_maps(b: usize, d: usize, side: usize, device: &Device) -> Vec<Tensor<4>> {
    let mut s = side;
    (0..6)
        .map(|i| {
            s /= 2;
            let c = RGB_CHANNELS.get(i).copied().unwrap_or(d);
            Tensor::zeros([b, c, s, s], device)
        })
        .collect()
}

/// The reconstruction model's decoders: RGB through six convolutions with
/// upsampling (sigmoid at the end), the last wrench reading and
/// proprioception through four-layer MLPs.
#[derive(Module, Debug)]
pub struct ReconDecoders {
    pub(crate) rgb_fc: Linear,
    pub(crate) rgb_convs: Vec<Conv2d>,
    pub(crate) wrench: LeakyMlp,
    pub(crate) proprio: LeakyMlp,
}

/// Channels of the RGB reconstruction's six convolutions.
const RECON_CHANNELS: [usize; 6] = [64, 64, 32, 32, 16, 3];
/// Channels of the map the RGB reconstruction starts from.
const RECON_START: usize = 64;

/// What the reconstruction model predicts.
#[derive(Debug, Clone)]
pub struct Reconstruction {
    /// RGB in 0..1, `[B, 3, S, S]`.
    pub rgb: Tensor<4>,
    /// The last wrench reading, normalised, `[B, 6]`.
    pub wrench: Tensor<2>,
    /// Proprioception, normalised, `[B, 8]`.
    pub proprio: Tensor<2>,
}

impl ReconDecoders {
    /// For latent size `d` and images of side `side`.
    pub fn new(d: usize, side: usize, device: &Device) -> Self {
        let cells = (side / IMAGE_DOWNSAMPLE).pow(2);
        let mut cin = RECON_START;
        let mut rgb_convs = Vec::new();
        for &cout in &RECON_CHANNELS {
            rgb_convs.push(conv3(cin, cout, device));
            cin = cout;
        }
        Self {
            rgb_fc: LinearConfig::new(d, RECON_START * cells).init(device),
            rgb_convs,
            wrench: LeakyMlp::new(&[d, 128, 64, 32, 6], device),
            proprio: LeakyMlp::new(&[d, 128, 64, 32, learner_node::proprio::PROPRIO], device),
        }
    }

    /// `z` `[B, d]` → the reconstruction of images of side `side`.
    pub fn forward(&self, z: Tensor<2>, side: usize) -> Reconstruction {
        let [b, _] = z.dims();
        let s = side / IMAGE_DOWNSAMPLE;
        let mut x = act(self.rgb_fc.forward(z.clone())).reshape([b, RECON_START, s, s]);
        let last = self.rgb_convs.len() - 1;
        for (i, c) in self.rgb_convs.iter().enumerate() {
            x = conv2d(c, upsample(x, 2));
            if i < last {
                x = act(x);
            }
        }
        Reconstruction {
            rgb: sigmoid(x),
            wrench: self.wrench.forward(z.clone()),
            proprio: self.proprio.forward(z),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::net::tensor;
    use super::*;
    use burn::tensor::module::interpolate;
    use burn::tensor::ops::{InterpolateMode, InterpolateOptions};

    fn burns(x: Tensor<4>, factor: usize) -> Tensor<4> {
        let [_, _, h, w] = x.dims();
        interpolate(
            x,
            InterpolateOptions::new(InterpolateMode::Bilinear)
                .with_align_corners(true)
                .with_output_size([h * factor, w * factor]),
        )
    }

    fn values(t: Tensor<4>) -> Vec<f32> {
        t.try_into_vec_as::<f32>().expect("an f32 tensor")
    }

    fn max_abs_difference(a: &[f32], b: &[f32]) -> f32 {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f32::max)
    }

    /// Our upsampling (`learner_kernels::upsample_bilinear` on flex) is burn's bilinear
    /// interpolation, in value and in gradient, on a non-square map at both
    /// factors the decoders use, and
    /// on maps one pixel high and one pixel square (the reconstruction
    /// decoder starts at side / 64: 1×1 for 64 px images).
    #[test]
    fn upsample_is_bilinear_interpolation_with_aligned_corners() {
        let dev = Device::flex().autodiff();
        let cases = [
            ([2, 3, 5, 7], 2),
            ([2, 3, 5, 7], 4),
            ([1, 2, 1, 3], 2),
            ([1, 2, 1, 1], 2),
        ];
        for (shape, factor) in cases {
            let [b, c, h, w] = shape;
            let n = b * c * h * w;
            let data: Vec<f32> = (0..n)
                .map(|i| ((i * 37 % 101) as f32) / 17.0 - 3.0)
                .collect();
            let x = tensor(data, shape, &dev).require_grad();
            let ours = upsample(x.clone(), factor);
            let theirs = burns(x.clone(), factor);
            let out = [b, c, h * factor, w * factor];
            assert_eq!(ours.dims(), out);
            let (a, bv) = (values(ours.clone()), values(theirs.clone()));
            let worst = max_abs_difference(&a, &bv);
            assert!(
                worst < 1e-5,
                "{shape:?} ×{factor}: values differ by {worst}"
            );
            // The same weights on the output give the same input gradient.
            let wv: Vec<f32> = (0..a.len()).map(|i| ((i * 13 % 29) as f32) / 7.0).collect();
            let wt = tensor(wv, out, &dev);
            let ga = (ours * wt.clone()).sum().backward();
            let gb = (theirs * wt).sum().backward();
            let (ga, gb) = (x.grad(&ga).unwrap(), x.grad(&gb).unwrap());
            let (ga, gb) = (values(ga), values(gb));
            let worst = max_abs_difference(&ga, &gb);
            assert!(
                worst < 1e-4,
                "{shape:?} ×{factor}: gradients differ by {worst}"
            );
        }
    }
}
