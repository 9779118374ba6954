//! Denormal floats flushed to zero on temc's worker threads, as OIDN does on its CPU
//! device. A model whose weights or activations fall into the subnormal range (the
//! `weights` fuzz target found a five-byte mutation of a test model that does) otherwise
//! runs 60x slower: x86 takes a microcode assist for every subnormal operand and result.
//! Flushing changes values only below f32's smallest normal (1.2e-38), far below anything
//! the pipeline resolves.

/// Sets flush-to-zero and denormals-are-zero for the calling thread (x86-64 MXCSR bits 15
/// and 6). Elsewhere a no-op: other targets keep IEEE subnormals.
pub(super) fn flush_to_zero() {
    #[cfg(target_arch = "x86_64")]
    {
        const FTZ_DAZ: u32 = (1 << 15) | (1 << 6);
        let mut csr: u32 = 0;
        // SAFETY: stmxcsr/ldmxcsr read and write this thread's SSE control register; only
        // the two flush bits change, and SSE is baseline on x86-64.
        unsafe {
            std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack, preserves_flags));
            csr |= FTZ_DAZ;
            std::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack, preserves_flags, readonly));
        }
    }
}

#[cfg(test)]
mod tests {
    use std::hint::black_box;

    /// On a flushing thread a subnormal operand reads as zero and a product that would be
    /// subnormal is zero; the thread that did not flush keeps IEEE behaviour.
    #[test]
    fn subnormals_are_zero_after_flushing() {
        let tiny = black_box(1.0e-39f32); // subnormal
        assert!(tiny * black_box(1.0f32) > 0.0, "IEEE by default");
        let flushed = std::thread::spawn(move || {
            super::flush_to_zero();
            (
                black_box(tiny) * black_box(1.0f32),
                black_box(1.0e-30f32) * black_box(1.0e-10f32),
            )
        })
        .join()
        .unwrap();
        if cfg!(target_arch = "x86_64") {
            assert_eq!(flushed, (0.0, 0.0));
        }
    }
}
