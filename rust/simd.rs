//! Four doubles at a time: one kernel, two instruction sets.
//!
//! The hot loops (`kernel`'s accumulation passes, `algebraic`'s scatter, `geometry`'s scan,
//! `sphere`'s error sums) are written once against [`Simd`], a vector of four `f64` lanes.
//! [`Portable`] implements it with plain arrays (SSE2, which every x86-64 has, or any other
//! CPU; multiply-adds are a multiply and an add, never a software `fma` call); [`Avx2`]
//! implements it with AVX2 + FMA instructions (one register per vector, fused multiply-adds).
//! An [`Avx2`] value exists only after [`Avx2::detect`] saw both features on this CPU, which is
//! what makes its `unsafe` intrinsic calls sound; each entry point picks one at run time
//! ([`dispatch!`]). This module holds the crate's only `unsafe` code. Results agree to
//! rounding (a fused multiply-add rounds once where a multiply and an add round twice).

/// A vector of four `f64` lanes and the operations the kernels need. Masks are vectors whose
/// lanes have all bits set (true) or none (false).
pub(crate) trait Simd: Copy {
    /// The vector type.
    type V: Copy;
    /// All lanes `x`.
    fn splat(self, x: f64) -> Self::V;
    /// The lanes of `a`.
    fn vector(self, a: [f64; 4]) -> Self::V;
    /// The lanes as an array.
    fn to_array(self, v: Self::V) -> [f64; 4];
    /// Four points `[x, y, z]` as the vectors of their x, y and z.
    fn load_xyz(self, p: &[[f64; 3]; 4]) -> [Self::V; 3];
    /// `a + b`.
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a - b`.
    fn sub(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a * b`.
    fn mul(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a / b`.
    fn div(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a * b + c` (fused where the instruction set has it).
    fn fma(self, a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    /// `√a`.
    fn sqrt(self, a: Self::V) -> Self::V;
    /// `|a|`.
    fn abs(self, a: Self::V) -> Self::V;
    /// `max(a, b)` (`b` where either is NaN).
    fn max(self, a: Self::V, b: Self::V) -> Self::V;
    /// Mask of `a > b`.
    fn gt(self, a: Self::V, b: Self::V) -> Self::V;
    /// Mask of `a >= b`.
    fn ge(self, a: Self::V, b: Self::V) -> Self::V;
    /// Bitwise `a & b` (with a mask: `b` where true, 0 where false).
    fn and(self, a: Self::V, b: Self::V) -> Self::V;
    /// Bitwise `!a & b`.
    fn andnot(self, a: Self::V, b: Self::V) -> Self::V;
    /// The sign bits of the lanes, lane `l` in bit `l` (with a mask: which lanes are true).
    fn sign_bits(self, a: Self::V) -> u32;
    /// The 4 x 4 transpose: lane `l` of output `k` is lane `k` of input `l`.
    fn transpose(self, r: [Self::V; 4]) -> [Self::V; 4];
    /// `Σ` of the lanes, as `(l0 + l1) + (l2 + l3)`.
    #[inline(always)]
    fn sum(self, v: Self::V) -> f64 {
        let a = self.to_array(v);
        (a[0] + a[1]) + (a[2] + a[3])
    }
    /// All lanes zero.
    #[inline(always)]
    fn zero(self) -> Self::V {
        self.splat(0.0)
    }
}

/// Plain arrays: compiles to whatever the target offers (SSE2 on x86-64).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Portable;

macro_rules! lanes {
    (|$($x:ident),+| $e:expr) => {
        [
            { $(let $x = $x[0];)+ $e },
            { $(let $x = $x[1];)+ $e },
            { $(let $x = $x[2];)+ $e },
            { $(let $x = $x[3];)+ $e },
        ]
    };
}

/// `[f(0), f(1), f(2)]` written out (array `map` with a closure is not reliably inlined into
/// the AVX2 functions, and an intrinsic that is not inlined there is a function call).
macro_rules! arr3 {
    (|$i:ident| $e:expr) => {
        [{ let $i = 0usize; $e }, { let $i = 1usize; $e }, { let $i = 2usize; $e }]
    };
}
pub(crate) use arr3;

#[inline(always)]
fn bits(x: f64) -> u64 {
    x.to_bits()
}

#[inline(always)]
fn mask(b: bool) -> f64 {
    f64::from_bits(if b { u64::MAX } else { 0 })
}

impl Simd for Portable {
    type V = [f64; 4];
    #[inline(always)]
    fn splat(self, x: f64) -> [f64; 4] {
        [x; 4]
    }
    #[inline(always)]
    fn vector(self, a: [f64; 4]) -> [f64; 4] {
        a
    }
    #[inline(always)]
    fn to_array(self, v: [f64; 4]) -> [f64; 4] {
        v
    }
    #[inline(always)]
    fn load_xyz(self, p: &[[f64; 3]; 4]) -> [[f64; 4]; 3] {
        arr3!(|k| [p[0][k], p[1][k], p[2][k], p[3][k]])
    }
    #[inline(always)]
    fn add(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        lanes!(|a, b| a + b)
    }
    #[inline(always)]
    fn sub(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        lanes!(|a, b| a - b)
    }
    #[inline(always)]
    fn mul(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        lanes!(|a, b| a * b)
    }
    #[inline(always)]
    fn div(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        lanes!(|a, b| a / b)
    }
    #[inline(always)]
    fn fma(self, a: [f64; 4], b: [f64; 4], c: [f64; 4]) -> [f64; 4] {
        lanes!(|a, b, c| a * b + c)
    }
    #[inline(always)]
    fn sqrt(self, a: [f64; 4]) -> [f64; 4] {
        lanes!(|a| a.sqrt())
    }
    #[inline(always)]
    fn abs(self, a: [f64; 4]) -> [f64; 4] {
        lanes!(|a| a.abs())
    }
    #[inline(always)]
    fn max(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        lanes!(|a, b| if a > b { a } else { b })
    }
    #[inline(always)]
    fn gt(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        lanes!(|a, b| mask(a > b))
    }
    #[inline(always)]
    fn ge(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        lanes!(|a, b| mask(a >= b))
    }
    #[inline(always)]
    fn and(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        lanes!(|a, b| f64::from_bits(bits(a) & bits(b)))
    }
    #[inline(always)]
    fn andnot(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        lanes!(|a, b| f64::from_bits(!bits(a) & bits(b)))
    }
    #[inline(always)]
    fn sign_bits(self, a: [f64; 4]) -> u32 {
        let s = lanes!(|a| (bits(a) >> 63) as u32);
        s[0] | (s[1] << 1) | (s[2] << 2) | (s[3] << 3)
    }
    #[inline(always)]
    fn transpose(self, r: [[f64; 4]; 4]) -> [[f64; 4]; 4] {
        std::array::from_fn(|k| [r[0][k], r[1][k], r[2][k], r[3][k]])
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) use avx2::Avx2;

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod avx2 {
    use super::Simd;
    use std::arch::x86_64::*;

    /// AVX2 + FMA. A value of this type proves that the CPU has both features: the only way
    /// to make one is [`Avx2::detect`].
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct Avx2 {
        _private: (),
    }

    impl Avx2 {
        /// `Some` when this CPU has AVX2 and FMA, unless the environment variable
        /// `TRIAXCAL_PORTABLE` is set (to measure the portable build on the same machine).
        /// Decided once per process.
        #[inline(always)]
        pub(crate) fn detect() -> Option<Avx2> {
            use std::sync::atomic::{AtomicU8, Ordering};
            static STATE: AtomicU8 = AtomicU8::new(0); // 0 unknown, 1 yes, 2 no
            let mut state = STATE.load(Ordering::Relaxed);
            if state == 0 {
                let yes = is_x86_feature_detected!("avx2")
                    && is_x86_feature_detected!("fma")
                    && std::env::var_os("TRIAXCAL_PORTABLE").is_none();
                state = if yes { 1 } else { 2 };
                STATE.store(state, Ordering::Relaxed);
            }
            (state == 1).then_some(Avx2 { _private: () })
        }
    }

    // SAFETY (every `unsafe` block below): the intrinsics need AVX (and FMA for the
    // multiply-add); a value of `Avx2` exists only when `detect` found AVX2 and FMA on this
    // CPU. The two memory accesses read 12 and write 4 doubles inside the arrays they are given.
    impl Simd for Avx2 {
        type V = __m256d;
        #[inline(always)]
        fn splat(self, x: f64) -> __m256d {
            unsafe { _mm256_set1_pd(x) }
        }
        #[inline(always)]
        fn vector(self, a: [f64; 4]) -> __m256d {
            unsafe { _mm256_loadu_pd(a.as_ptr()) }
        }
        #[inline(always)]
        fn to_array(self, v: __m256d) -> [f64; 4] {
            let mut out = [0.0; 4];
            unsafe { _mm256_storeu_pd(out.as_mut_ptr(), v) };
            out
        }
        #[inline(always)]
        fn load_xyz(self, p: &[[f64; 3]; 4]) -> [__m256d; 3] {
            unsafe {
                let ptr = p.as_ptr().cast::<f64>();
                let v0 = _mm256_loadu_pd(ptr); // x0 y0 z0 x1
                let v1 = _mm256_loadu_pd(ptr.add(4)); // y1 z1 x2 y2
                let v2 = _mm256_loadu_pd(ptr.add(8)); // z2 x3 y3 z3
                let t0 = _mm256_permute2f128_pd::<0x30>(v0, v1); // x0 y0 x2 y2
                let t1 = _mm256_permute2f128_pd::<0x21>(v0, v2); // z0 x1 z2 x3
                let t2 = _mm256_permute2f128_pd::<0x30>(v1, v2); // y1 z1 y3 z3
                [
                    _mm256_shuffle_pd::<0b1010>(t0, t1),
                    _mm256_shuffle_pd::<0b0101>(t0, t2),
                    _mm256_shuffle_pd::<0b1010>(t1, t2),
                ]
            }
        }
        #[inline(always)]
        fn add(self, a: __m256d, b: __m256d) -> __m256d {
            unsafe { _mm256_add_pd(a, b) }
        }
        #[inline(always)]
        fn sub(self, a: __m256d, b: __m256d) -> __m256d {
            unsafe { _mm256_sub_pd(a, b) }
        }
        #[inline(always)]
        fn mul(self, a: __m256d, b: __m256d) -> __m256d {
            unsafe { _mm256_mul_pd(a, b) }
        }
        #[inline(always)]
        fn div(self, a: __m256d, b: __m256d) -> __m256d {
            unsafe { _mm256_div_pd(a, b) }
        }
        #[inline(always)]
        fn fma(self, a: __m256d, b: __m256d, c: __m256d) -> __m256d {
            unsafe { _mm256_fmadd_pd(a, b, c) }
        }
        #[inline(always)]
        fn sqrt(self, a: __m256d) -> __m256d {
            unsafe { _mm256_sqrt_pd(a) }
        }
        #[inline(always)]
        fn abs(self, a: __m256d) -> __m256d {
            unsafe { _mm256_andnot_pd(_mm256_set1_pd(-0.0), a) }
        }
        #[inline(always)]
        fn max(self, a: __m256d, b: __m256d) -> __m256d {
            unsafe { _mm256_max_pd(a, b) }
        }
        #[inline(always)]
        fn gt(self, a: __m256d, b: __m256d) -> __m256d {
            unsafe { _mm256_cmp_pd::<_CMP_GT_OQ>(a, b) }
        }
        #[inline(always)]
        fn ge(self, a: __m256d, b: __m256d) -> __m256d {
            unsafe { _mm256_cmp_pd::<_CMP_GE_OQ>(a, b) }
        }
        #[inline(always)]
        fn and(self, a: __m256d, b: __m256d) -> __m256d {
            unsafe { _mm256_and_pd(a, b) }
        }
        #[inline(always)]
        fn andnot(self, a: __m256d, b: __m256d) -> __m256d {
            unsafe { _mm256_andnot_pd(a, b) }
        }
        #[inline(always)]
        fn sign_bits(self, a: __m256d) -> u32 {
            unsafe { _mm256_movemask_pd(a) as u32 }
        }
        #[inline(always)]
        fn transpose(self, r: [__m256d; 4]) -> [__m256d; 4] {
            unsafe {
                let t0 = _mm256_unpacklo_pd(r[0], r[1]); // r0[0] r1[0] r0[2] r1[2]
                let t1 = _mm256_unpackhi_pd(r[0], r[1]); // r0[1] r1[1] r0[3] r1[3]
                let t2 = _mm256_unpacklo_pd(r[2], r[3]);
                let t3 = _mm256_unpackhi_pd(r[2], r[3]);
                [
                    _mm256_permute2f128_pd::<0x20>(t0, t2),
                    _mm256_permute2f128_pd::<0x20>(t1, t3),
                    _mm256_permute2f128_pd::<0x31>(t0, t2),
                    _mm256_permute2f128_pd::<0x31>(t1, t3),
                ]
            }
        }
    }
}

/// Whether this CPU has AVX2 and FMA (and `TRIAXCAL_PORTABLE` is not set): see
/// [`Avx2::detect`]. For kernels that keep their own `#[target_feature]` twin and call it with
/// [`avx2_call!`] instead of going through [`dispatch!`].
#[inline(always)]
pub fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        Avx2::detect().is_some()
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
#[allow(unused_imports)]
pub(crate) use avx2_call;

/// Runs `$body` with `$s` bound to the best [`Simd`] of this CPU: [`Avx2`] inside a function
/// compiled for AVX2 + FMA when the CPU has them, [`Portable`] otherwise. `$body` should call
/// `#[inline(always)]` code generic over `S: Simd`, which is then compiled for each.
macro_rules! dispatch {
    (|$s:ident| $body:expr) => {{
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2,fma")]
            #[inline]
            fn with_avx2<R>(f: impl FnOnce() -> R) -> R {
                f()
            }
            match $crate::simd::Avx2::detect() {
                Some($s) => {
                    // SAFETY: `detect` found AVX2 and FMA on this CPU.
                    #[allow(unsafe_code)]
                    unsafe {
                        with_avx2(
                            #[inline(always)]
                            || $body,
                        )
                    }
                }
                None => {
                    let $s = $crate::simd::Portable;
                    $body
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let $s = $crate::simd::Portable;
            $body
        }
    }};
}
pub(crate) use dispatch;
