//! Which implementation the operations run: the A/B switch of the
//! benchmarks, and a way to rule this crate's kernels out. A process-wide
//! setting, read when an operation is called; the default is this crate's
//! kernels with the small maps grouped ([`DEFAULT_GROUPED_OUTS`]).

use std::sync::RwLock;

/// The implementation of the training operations.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum KernelChoice {
    /// This crate's passes on `flex`, with the direct convolution kernels
    /// where the CPU has AVX and FMA (the default).
    #[default]
    Ours,
    /// This crate's passes, but every convolution's products through faer
    /// rather than the direct kernels (the A/B switch of those kernels).
    Products,
    /// burn's own operations throughout: its convolutions, and each other
    /// operation as the composition of burn's primitives it replaced
    /// (the A/B switch of the training benchmark).
    Burn,
}

impl KernelChoice {
    /// Every choice, the default first.
    pub const ALL: [KernelChoice; 3] = [Self::Ours, Self::Products, Self::Burn];

    /// Its name on a command line: `ours`, `products` or `burn`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Ours => "ours",
            Self::Products => "products",
            Self::Burn => "burn",
        }
    }
}

impl std::str::FromStr for KernelChoice {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|c| c.name() == s)
            .ok_or_else(|| format!("kernels {s:?}: expected ours, products or burn"))
    }
}

/// Output maps of at most this many positions (the encoders' 4² and 2²
/// outputs, the flow decoder's first two up-convolutions, the
/// Reconstruction Model decoder's first layer) run each convolution pass as
/// one product over a group of samples. Per sample a tap's product has
/// only 6–24 columns, where faer ran at 9–36 GFLOP/s and PyTorch's layers
/// of these shapes about twice as fast as ours. The 8² maps (64 positions)
/// measured slower grouped (docs/performance.md).
pub const DEFAULT_GROUPED_OUTS: usize = 16;

/// The kernels' settings: [`KernelChoice`] and the grouped convolution's
/// threshold.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct KernelSettings {
    /// Which implementation runs.
    pub choice: KernelChoice,
    /// Convolutions whose output map (an up-convolution's: its input map)
    /// has at most this many positions take the grouped passes; 0: none.
    pub grouped_outs: usize,
}

impl KernelSettings {
    /// This crate's kernels, [`DEFAULT_GROUPED_OUTS`].
    pub const DEFAULT: Self = Self {
        choice: KernelChoice::Ours,
        grouped_outs: DEFAULT_GROUPED_OUTS,
    };

    /// Whether the operations are burn's own ([`KernelChoice::Burn`]).
    pub fn burns_own(&self) -> bool {
        self.choice == KernelChoice::Burn
    }

    /// Whether the convolutions keep faer's products everywhere
    /// ([`KernelChoice::Products`]).
    pub fn products_only(&self) -> bool {
        self.choice == KernelChoice::Products
    }
}

impl Default for KernelSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

static SETTINGS: RwLock<KernelSettings> = RwLock::new(KernelSettings::DEFAULT);

/// Sets the kernels every later operation call of this process runs (set
/// it before a model's forward pass: a backward pass runs the passes of the
/// choice in force when it runs).
pub fn set_kernel_settings(settings: KernelSettings) {
    *SETTINGS.write().unwrap_or_else(|e| e.into_inner()) = settings;
}

/// [`set_kernel_settings`] with `choice` and the current grouped threshold.
pub fn set_kernel_choice(choice: KernelChoice) {
    set_kernel_settings(KernelSettings {
        choice,
        ..kernel_settings()
    });
}

/// The settings in force ([`KernelSettings::DEFAULT`] unless set).
pub fn kernel_settings() -> KernelSettings {
    *SETTINGS.read().unwrap_or_else(|e| e.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back() {
        for c in KernelChoice::ALL {
            assert_eq!(c.name().parse::<KernelChoice>(), Ok(c));
        }
        assert!("faer".parse::<KernelChoice>().is_err());
        assert_eq!(KernelSettings::default(), KernelSettings::DEFAULT);
        assert_eq!(KernelChoice::default(), KernelChoice::Ours);
    }
}
