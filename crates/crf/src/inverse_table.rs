//! Each channel's transfer law inverted once into a table, so that a pixel costs a
//! square root and a lookup instead of the law's own inverse (a power, a logarithm, or
//! a search through a measured table).
//!
//! The table is indexed by s = √a, a the channel's excitation as a share of full drive:
//! display laws are near powers of 2 to 2.6, so the drive is near a power of 0.8 of s,
//! which a linear interpolation follows closely everywhere, dark end included (a table
//! indexed by a itself would need millions of entries there). With 4096 entries the
//! drive found is within 2 × 10⁻⁵ of the exact inverse over the ISETBio, preset and
//! fitted laws; `crf::tests` and `tests/render.rs` hold the round trip through it.

use chromacal_model::transfer::TransferLaw;

/// Entries of each table.
pub const TABLE_SIZE: usize = 4096;

/// Entries of each table of 16-bit codes. Nearest-neighbour in s, the code is within
/// half a step of s times the drive's slope there: a 16-bit code or two (four near
/// black, where a code is no light).
pub const CODE_TABLE_SIZE: usize = 32768;

/// The inverse of one law, tabulated.
#[derive(Debug, Clone, PartialEq)]
pub struct InverseTable {
    /// Drive at s = k / (TABLE_SIZE − 1), i.e. at excitation E(1) s².
    drives: Vec<f64>,
    /// 16-bit codes at s = k / (CODE_TABLE_SIZE − 1), nearest-neighbour, for the batch
    /// loop: one load a channel, 64 KB a table (a fixed size, so that an index kept
    /// below it needs no bounds check).
    codes: Box<[u16; CODE_TABLE_SIZE]>,
}

impl InverseTable {
    pub fn of(law: &TransferLaw) -> InverseTable {
        let full = law.full_drive_excitation();
        let last = (TABLE_SIZE - 1) as f64;
        let drives: Vec<f64> = (0..TABLE_SIZE)
            .map(|k| {
                let s = k as f64 / last;
                law.drive(full * s * s)
            })
            .collect();
        let mut codes = Box::new([0u16; CODE_TABLE_SIZE]);
        let last_code = (CODE_TABLE_SIZE - 1) as f64;
        for (k, code) in codes.iter_mut().enumerate() {
            let s = k as f64 / last_code;
            *code = (law.drive(full * s * s).clamp(0.0, 1.0) * 65535.0).round() as u16;
        }
        InverseTable { codes, drives }
    }

    /// The drive giving `share` of the channel's full excitation (clamped to [0, 1]).
    #[inline]
    pub fn drive(&self, share: f64) -> f64 {
        let s = share.clamp(0.0, 1.0).sqrt();
        let p = s * (TABLE_SIZE - 1) as f64;
        let i = (p as usize).min(TABLE_SIZE - 2);
        let t = p - i as f64;
        self.drives[i] + t * (self.drives[i + 1] - self.drives[i])
    }
}

/// Pixels a batch handles at a time.
pub const BLOCK: usize = 256;

/// 16-bit codes of a block of pixels from each channel's excitation over its full
/// (`shares[c][j]`, any value), through `tables`: first the table positions
/// √share · (N − 1), channel by channel in loops the compiler vectorises; then one
/// lookup a channel.
pub fn codes16_of_shares(
    tables: [&InverseTable; 3],
    shares: &mut [[f32; BLOCK]; 3],
    n: usize,
    out: &mut [[u16; 3]],
) {
    let scale = (CODE_TABLE_SIZE - 1) as f32;
    for channel in shares.iter_mut() {
        for s in channel.iter_mut() {
            // NaN (a zero gain) stays NaN, and a NaN index casts to 0: black.
            *s = s.clamp(0.0, 1.0).sqrt() * scale + 0.5;
        }
    }
    for c in 0..3 {
        let table: &[u16; CODE_TABLE_SIZE] = &tables[c].codes;
        for (o, p) in out[..n].iter_mut().zip(&shares[c][..n]) {
            o[c] = table[(*p as usize).min(CODE_TABLE_SIZE - 1)];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_model::transfer::{Cowan, GainOffsetGamma, Power};

    #[test]
    fn the_table_follows_the_exact_inverse() {
        for law in [
            TransferLaw::Power(Power { gamma: 2.2 }),
            TransferLaw::GainOffsetGamma(GainOffsetGamma::from_cutoff(0.05, 2.4)),
            TransferLaw::Cowan(Cowan {
                a: 2.3,
                b: 0.06,
                toe: 1.0 / 255.0,
            }),
        ] {
            let table = InverseTable::of(&law);
            let full = law.full_drive_excitation();
            let mut worst: f64 = 0.0;
            for k in 1..=100_000 {
                let share = k as f64 / 100_000.0;
                // Where the law gives light at all (below a cut-off every drive is 0).
                if share < 1e-6 {
                    continue;
                }
                let exact = law.drive(full * share);
                worst = worst.max((table.drive(share) - exact).abs());
            }
            assert!(worst < 2e-5, "{law:?}: {worst}");
        }
    }
}
