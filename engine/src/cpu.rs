//! The CPU features the hot loops dispatch on at run time (one check for all of them).

/// Whether this CPU has AVX. The small scenes' triangle blocks, the gather's camera path
/// and the photon tracer each have a copy compiled for it, which give the same results as
/// the portable code (tested) and run where this is true.
pub fn has_avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
