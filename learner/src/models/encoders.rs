//! The four modality encoders (paper, "Modality Encoders"). Each maps its
//! input to 2·d values: the mean and the raw variance parameters of a
//! d-dimensional Gaussian (the deterministic model uses the same 2·d values
//! as a feature vector).

use burn::nn::conv::{Conv1d, Conv1dConfig, Conv2d, Conv2dConfig};
use burn::nn::{Linear, LinearConfig, PaddingConfig2d};
use burn::prelude::*;

use learner_kernels::conv2d;

/// Slope of every leaky ReLU (the authors' code uses 0.1).
pub const LEAKY_SLOPE: f64 = 0.1;

/// Six stride-2 layers bring an image of side S to S/64.
pub const IMAGE_DOWNSAMPLE: usize = 64;

/// Leaky ReLU with [`LEAKY_SLOPE`]: [`learner_kernels::leaky_relu`], one
/// operation with its own backward pass (one pass each way on the CPU;
/// burn's primitives under `KernelChoice::Burn`, the benchmark's A/B
/// switch).
pub fn act<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    learner_kernels::leaky_relu(x, LEAKY_SLOPE)
}

/// A multilayer perceptron: leaky ReLU between layers, none after the last.
#[derive(Module, Debug)]
pub struct LeakyMlp {
    pub(crate) layers: Vec<Linear>,
}

impl LeakyMlp {
    /// Layers of the widths `widths[0] → widths[1] → … → widths[n]`.
    pub fn new(widths: &[usize], device: &Device) -> Self {
        Self {
            layers: widths
                .windows(2)
                .map(|w| LinearConfig::new(w[0], w[1]).init(device))
                .collect(),
        }
    }

    /// Applies it to `[B, widths[0]]`.
    pub fn forward(&self, mut x: Tensor<2>) -> Tensor<2> {
        let last = self.layers.len().saturating_sub(1);
        for (i, l) in self.layers.iter().enumerate() {
            x = l.forward(x);
            if i < last {
                x = act(x);
            }
        }
        x
    }
}

fn conv(cin: usize, cout: usize, k: usize, stride: usize, device: &Device) -> Conv2d {
    let p = (k - 1) / 2;
    Conv2dConfig::new([cin, cout], [k, k])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
        .init(device)
}

/// Channels after each of the RGB encoder's layers but the last (which has
/// d): FlowNet-like widths, as the authors' code.
pub const RGB_CHANNELS: [usize; 5] = [16, 32, 64, 64, 128];
const RGB_KERNELS: [usize; 6] = [7, 5, 5, 3, 3, 3];

/// The RGB encoder: a six-layer FlowNet-like CNN, each layer stride 2, and
/// one fully connected layer. Its feature maps are the flow decoder's skip
/// connections.
#[derive(Module, Debug)]
pub struct RgbEncoder {
    pub(crate) convs: Vec<Conv2d>,
    pub(crate) fc: Linear,
}

impl RgbEncoder {
    /// For images of side `side` and latent size `d`.
    pub fn new(d: usize, side: usize, device: &Device) -> Self {
        let mut cin = 3;
        let mut convs = Vec::new();
        for (i, &k) in RGB_KERNELS.iter().enumerate() {
            let cout = RGB_CHANNELS.get(i).copied().unwrap_or(d);
            convs.push(conv(cin, cout, k, 2, device));
            cin = cout;
        }
        let cells = (side / IMAGE_DOWNSAMPLE).pow(2);
        Self {
            convs,
            fc: LinearConfig::new(d * cells, 2 * d).init(device),
        }
    }

    /// `[B, 3, S, S]` → (`[B, 2d]`, the six feature maps, finest first).
    pub fn forward(&self, mut x: Tensor<4>) -> (Tensor<2>, Vec<Tensor<4>>) {
        let mut maps = Vec::with_capacity(self.convs.len());
        for c in &self.convs {
            x = act(conv2d(c, x));
            maps.push(x.clone());
        }
        (self.fc.forward(x.flatten(1, 3)), maps)
    }
}

/// Channels of the depth encoder's six stages but the last (which has d).
const DEPTH_CHANNELS: [usize; 5] = [16, 32, 64, 64, 128];

/// The depth encoder: a VGG-like CNN of 3×3 convolutions in six stages
/// (the first convolution of each stage has stride 2), `convs_per_stage`
/// each (3: the paper's eighteen layers), and one fully connected layer.
#[derive(Module, Debug)]
pub struct DepthEncoder {
    pub(crate) convs: Vec<Conv2d>,
    pub(crate) fc: Linear,
}

impl DepthEncoder {
    /// For images of side `side` and latent size `d`.
    pub fn new(d: usize, side: usize, convs_per_stage: usize, device: &Device) -> Self {
        let mut cin = 1;
        let mut convs = Vec::new();
        for stage in 0..6 {
            let cout = DEPTH_CHANNELS.get(stage).copied().unwrap_or(d);
            for j in 0..convs_per_stage {
                convs.push(conv(cin, cout, 3, if j == 0 { 2 } else { 1 }, device));
                cin = cout;
            }
        }
        let cells = (side / IMAGE_DOWNSAMPLE).pow(2);
        Self {
            convs,
            fc: LinearConfig::new(d * cells, 2 * d).init(device),
        }
    }

    /// `[B, 1, S, S]` → `[B, 2d]`.
    pub fn forward(&self, mut x: Tensor<4>) -> Tensor<2> {
        for c in &self.convs {
            x = act(conv2d(c, x));
        }
        self.fc.forward(x.flatten(1, 3))
    }
}

/// Channels after each causal convolution of the wrench encoder but the
/// last (which has 2·d).
const WRENCH_CHANNELS: [usize; 4] = [16, 32, 64, 128];

/// The haptics encoder: five causal 1-D convolutions of stride 2 over the
/// 32×6 wrench window (32 → 16 → 8 → 4 → 2 → 1 steps). Kernel and stride
/// are both 2, so each output sees only its own two inputs, none later than
/// itself: causal without padding (left padding would drop the newest
/// reading from the first layer).
#[derive(Module, Debug)]
pub struct WrenchEncoder {
    pub(crate) convs: Vec<Conv1d>,
}

impl WrenchEncoder {
    /// For latent size `d`.
    pub fn new(d: usize, device: &Device) -> Self {
        let mut cin = 6;
        let mut convs = Vec::new();
        for i in 0..5 {
            let cout = WRENCH_CHANNELS.get(i).copied().unwrap_or(2 * d);
            convs.push(Conv1dConfig::new(cin, cout, 2).with_stride(2).init(device));
            cin = cout;
        }
        Self { convs }
    }

    /// `[B, 6, 32]` → `[B, 2d]`.
    pub fn forward(&self, mut x: Tensor<3>) -> Tensor<2> {
        let last = self.convs.len() - 1;
        for (i, c) in self.convs.iter().enumerate() {
            x = c.forward(x);
            if i < last {
                x = act(x);
            }
        }
        x.flatten(1, 2)
    }
}

/// The proprioception encoder: a four-layer MLP 8 → 32 → 64 → 128 → 2·d.
#[derive(Module, Debug)]
pub struct ProprioEncoder {
    pub(crate) mlp: LeakyMlp,
}

impl ProprioEncoder {
    /// For latent size `d`.
    pub fn new(d: usize, device: &Device) -> Self {
        Self {
            mlp: LeakyMlp::new(
                &[learner_node::proprio::PROPRIO, 32, 64, 128, 2 * d],
                device,
            ),
        }
    }

    /// `[B, 8]` → `[B, 2d]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        self.mlp.forward(x)
    }
}
