//! Subnormal floats flushed to zero on the threads that trace (DESIGN.md §7: throughput).
//!
//! A float below 1.2e-38 is subnormal, and on Intel cores an SSE or AVX operation that reads or
//! produces one takes a microcode assist of about a hundred cycles. No radiance, direction or
//! distance of ours means anything at that scale, so the tracing threads set the MXCSR's
//! flush-to-zero and denormals-are-zero bits: such values become 0 at the cost of nothing.
//! MXCSR is per thread, so the bits are set at the start of each unit of parallel work (a
//! batch's point, a reference image's row), whichever pool runs it.

/// The variable that keeps subnormals (`WALKTHROUGH_SUBNORMALS=keep`), to measure the flush.
pub const VAR: &str = "WALKTHROUGH_SUBNORMALS";

/// Sets flush-to-zero and denormals-are-zero on the calling thread (x86-64; elsewhere nothing),
/// unless [`VAR`] asks to keep subnormals.
pub fn flush_on_this_thread() {
    #[cfg(target_arch = "x86_64")]
    if flush_wanted() {
        set_ftz_daz();
    }
}

#[cfg(target_arch = "x86_64")]
fn set_ftz_daz() {
    /// MXCSR bit 15 (flush to zero) and bit 6 (denormals are zero).
    const FTZ_DAZ: u32 = (1 << 15) | (1 << 6);
    let mut csr: u32 = 0;
    // SAFETY: stmxcsr stores the 32-bit MXCSR into `csr`, a valid, aligned u32 of ours; ldmxcsr
    // loads it back with two bits set that change only how subnormals are handled (no exception
    // is unmasked, no reserved bit is set).
    unsafe {
        std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack, preserves_flags));
        csr |= FTZ_DAZ;
        std::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack, readonly, preserves_flags));
    }
}

#[cfg(target_arch = "x86_64")]
fn flush_wanted() -> bool {
    static WANTED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *WANTED.get_or_init(|| std::env::var(VAR).map_or(true, |v| v.trim() != "keep"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn a_subnormal_result_becomes_zero_on_a_flushed_thread() {
        let (tiny, half) = (
            std::hint::black_box(f32::MIN_POSITIVE),
            std::hint::black_box(0.5f32),
        );
        assert!(tiny * half > 0.0, "subnormals kept before the flush");
        let flushed = std::thread::spawn(move || {
            set_ftz_daz();
            std::hint::black_box(tiny) * std::hint::black_box(half)
        })
        .join()
        .unwrap();
        assert_eq!(flushed, 0.0);
    }
}
