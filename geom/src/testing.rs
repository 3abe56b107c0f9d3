//! What the crate's tests share: a small deterministic generator (xorshift64), so that
//! random cases repeat and a failure can be replayed from its seed. The crate sits
//! below every other, so it cannot use `lamina-test-support`'s.

pub(crate) struct Rng(pub u64);

impl Rng {
    fn step(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// The next number, uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.step() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// The next number in `0..m`.
    pub fn below(&mut self, m: u64) -> u64 {
        self.step() % m
    }
}
