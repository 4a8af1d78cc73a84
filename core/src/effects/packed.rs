//! The changes and partials of [`super::Corrections`], packed: each [`Delta`] kept as the fields that
//! are not zero. A partial is one effect parameter's derivative of one pose's change, and an
//! effect moves few of a pose's inputs (an encoder's scale one carrier position, thermal
//! expansion the lengths): whole, a partial is 37 numbers (296 bytes), and the partials of a
//! candidate's model over 10⁵ poses held 243 MB per evaluation. Each is unpacked to the same
//! [`Delta`], bit for bit, where it is read: every sum over it is the same.

use super::effect::Delta;
use crate::params::N_PARAMS;

/// Where each field of a [`Delta`] is in the packing: dp, then dq, dm, dpsi, dk.
const DQ: usize = N_PARAMS;
const DM: usize = DQ + 4;
const DPSI: usize = DM + 2;
const DK: usize = DPSI + 1;

/// Changes (or partials), each its index (a pose's, or a θ index) and its fields that are not +0.0 (a −0.0 is kept: the
/// unpacked value is the packed one to the bit).
#[derive(Clone, Debug, Default)]
pub(super) struct Packed {
    /// Per partial: the θ index.
    index: Vec<usize>,
    /// Per partial, where its fields start in `fields` and `values` (one more entry: the
    /// end).
    starts: Vec<usize>,
    fields: Vec<u8>,
    values: Vec<f64>,
}

impl Packed {
    pub fn with_capacity(partials: usize) -> Packed {
        Packed {
            index: Vec::with_capacity(partials),
            starts: Vec::with_capacity(partials + 1),
            fields: Vec::new(),
            values: Vec::new(),
        }
    }

    /// How many partials.
    pub fn len(&self) -> usize {
        self.index.len()
    }

    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// Appends the partial `d` of θ index `k`.
    pub fn push(&mut self, k: usize, d: &Delta) {
        if self.starts.is_empty() {
            self.starts.push(0);
        }
        self.index.push(k);
        let fields =
            d.dp.iter()
                .chain(&d.dq)
                .chain(d.dm.iter())
                .chain([&d.dpsi, &d.dk])
                .enumerate();
        for (f, &v) in fields {
            if v.to_bits() != 0 {
                // DK + 1 = 37 fields: an index fits a byte
                self.fields.push(u8::try_from(f).unwrap_or(u8::MAX));
                self.values.push(v);
            }
        }
        self.starts.push(self.values.len());
    }

    /// Partial `n`: its θ index and its change, unpacked.
    pub fn get(&self, n: usize) -> (usize, Delta) {
        let mut d = Delta::default();
        let (a, b) = (self.starts[n], self.starts[n + 1]);
        for (&f, &v) in self.fields[a..b].iter().zip(&self.values[a..b]) {
            let f = usize::from(f);
            match f {
                _ if f < DQ => d.dp[f] = v,
                _ if f < DM => d.dq[f - DQ] = v,
                _ if f < DPSI => d.dm[f - DM] = v,
                DPSI => d.dpsi = v,
                DK => d.dk = v,
                // `push` packs no other field
                _ => {}
            }
        }
        (self.index[n], d)
    }

    /// Partials `range`, unpacked.
    pub fn range(
        &self,
        range: std::ops::Range<usize>,
    ) -> impl Iterator<Item = (usize, Delta)> + '_ {
        range.map(|n| self.get(n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unpacks_every_field_to_the_bit() {
        let mut d = Delta::default();
        d.dp[0] = 1.5;
        d.dp[28] = -0.0;
        d.dq[3] = 2.0e-9;
        d.dm[1] = -3.0;
        d.dpsi = 4.0;
        d.dk = f64::MIN_POSITIVE;
        let mut p = Packed::with_capacity(2);
        p.push(7, &Delta::default());
        p.push(3, &d);
        assert_eq!(p.len(), 2);
        let (k, back) = p.get(1);
        assert_eq!(k, 3);
        let bits = |d: &Delta| -> Vec<u64> {
            d.dp.iter()
                .chain(&d.dq)
                .chain(d.dm.iter())
                .chain([&d.dpsi, &d.dk])
                .map(|v| v.to_bits())
                .collect()
        };
        assert_eq!(bits(&back), bits(&d));
        assert_eq!(bits(&p.get(0).1), bits(&Delta::default()));
        // seven fields kept of the second, none of the first
        assert_eq!(p.values.len(), 6);
    }
}
