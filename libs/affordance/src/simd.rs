//! Which vector build of a hot loop this CPU runs. The loops are plain Rust written for
//! auto-vectorisation, compiled once per build below with wider registers enabled
//! (`#[target_feature]`); the caller picks the build once, at construction.

/// A vector build of a hot loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Simd {
    /// The target's baseline (SSE2 on x86-64).
    Baseline,
    /// AVX2 and FMA.
    Avx2,
    /// AVX-512F and FMA.
    Avx512,
}

impl Simd {
    /// The widest build this CPU runs.
    pub(crate) fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            let fma = std::arch::is_x86_feature_detected!("fma");
            if fma && std::arch::is_x86_feature_detected!("avx512f") {
                return Self::Avx512;
            }
            if fma && std::arch::is_x86_feature_detected!("avx2") {
                return Self::Avx2;
            }
        }
        Self::Baseline
    }

    /// Every build this CPU runs, narrowest first.
    #[cfg(test)]
    pub(crate) fn runnable() -> &'static [Self] {
        match Self::detect() {
            Self::Avx512 => &[Self::Baseline, Self::Avx2, Self::Avx512],
            Self::Avx2 => &[Self::Baseline, Self::Avx2],
            Self::Baseline => &[Self::Baseline],
        }
    }
}
