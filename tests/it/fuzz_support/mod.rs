//! The fuzzing tests' random stream: xorshift64*, fixed seeds, no dependency.
#![expect(
    clippy::cast_possible_truncation,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

/// xorshift64* (Vigna 2016): a fixed, dependency-free stream of cases.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// A number in 0..n (0 when n is 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }

    /// One of `items`.
    #[allow(dead_code)] // not every test binary picks
    pub fn pick<'a>(&mut self, items: &[&'a str]) -> &'a str {
        items[self.below(items.len())]
    }
}
