//! Run-time dispatch to AVX2 + FMA code on x86-64, with the portable build as the fallback.
//!
//! The hot loops (`ellipsoid`'s accumulation passes) are written lane-wise so that LLVM
//! vectorises them. The portable build may assume only SSE2 (2 doubles per instruction); on a
//! CPU with AVX2 and FMA the same code compiled for those features does 4 per instruction with
//! fused multiply-adds. Each kernel is an `#[inline(always)]` function with a
//! `#[target_feature(enable = "avx2,fma")]` twin that only calls it (so it is compiled again for
//! those features); [`has_avx2_fma`] picks one at run time and [`avx2_call!`] makes the call,
//! the crate's only `unsafe`. Results agree to rounding (FMA rounds once where mul + add rounds
//! twice).

/// Whether this CPU has AVX2 and FMA (cached by the standard library after the first call).
#[inline(always)]
pub fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Calls a `#[target_feature(enable = "avx2,fma")]` function. Use only after
/// [`has_avx2_fma`] returned true.
macro_rules! avx2_call {
    ($call:expr) => {{
        // SAFETY: the callee requires only AVX2 and FMA, and the caller checked
        // `has_avx2_fma()` before this call.
        #[allow(unsafe_code)]
        let out = unsafe { $call };
        out
    }};
}
pub(crate) use avx2_call;
