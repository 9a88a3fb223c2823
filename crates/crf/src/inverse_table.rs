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

/// The entry of a code table nearest √share · (N − 1), `share` clamped to [0, 1] and
/// NaN taken as 0 (black).
///
/// The float is rounded to an integer by adding 2²³, which leaves the nearest integer
/// (ties to even) in the low bits of the sum's mantissa for any value in [0, 2²³). A
/// cast (`as usize`) would round down after adding a half, but it saturates and sends
/// NaN to 0 lane by lane, and that keeps the loop from being vectorised: with it the
/// index took most of a pixel's time. `max` rather than `clamp` at the bottom: it
/// gives 0 for any NaN, where a NaN left through would give the index of whatever
/// payload it carries (a NaN of all ones bits is the last entry: white).
#[inline(always)]
#[allow(clippy::manual_clamp)] // `clamp` keeps NaN, which is the point of not using it
pub fn code_index(share: f32) -> u32 {
    const SCALE: f32 = (CODE_TABLE_SIZE - 1) as f32;
    const ROUND: f32 = 8_388_608.0;
    (share.max(0.0).min(1.0).sqrt() * SCALE + ROUND).to_bits() & (CODE_TABLE_SIZE as u32 - 1)
}

/// A profile's inverse as the batch loop reads it (a profile without additivity
/// terms): the inverse matrix's rows over each channel's full light, the black, and
/// each channel's table, in 32-bit floats.
#[derive(Debug, Clone, Copy)]
pub struct BatchInverse<'a> {
    pub rows: [[f32; 3]; 3],
    pub black: [f32; 3],
    pub tables: [&'a InverseTable; 3],
}

/// What the batch loop may be compiled for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Instructions {
    /// The best the processor has (AVX2 and FMA, say), found at run time by `pulp`.
    Best,
    /// The target's baseline: for the test that both give the same codes.
    Baseline,
}

impl BatchInverse<'_> {
    /// 16-bit codes of `xyz` (read as `f32` by `to_f32`) into `out`, each channel's
    /// light divided by `gains(k)` for pixel k where the screen is not uniform.
    ///
    /// Compiled again for the processor's best instructions when asked, the same
    /// operations in the same order (Rust fuses no multiply and add of its own): the
    /// same codes as the baseline build gives, as a test holds.
    pub fn codes16<T>(
        &self,
        xyz: &[T],
        to_f32: impl Fn(&T) -> [f32; 3],
        gains: Option<impl Fn(usize) -> [f64; 3]>,
        out: &mut [[u16; 3]],
        instructions: Instructions,
    ) {
        let batch = Batch {
            inverse: self,
            xyz,
            to_f32,
            gains,
            out,
        };
        match instructions {
            Instructions::Best => pulp::Arch::new().dispatch(batch),
            Instructions::Baseline => batch.run(),
        }
    }
}

/// One call of the batch loop, as `pulp` runs it (a closure would not be inlined into
/// the function it compiles for AVX2, and would run as the baseline built it).
struct Batch<'a, 'b, T, F, G> {
    inverse: &'a BatchInverse<'a>,
    xyz: &'b [T],
    to_f32: F,
    gains: Option<G>,
    out: &'b mut [[u16; 3]],
}

impl<T, F: Fn(&T) -> [f32; 3], G: Fn(usize) -> [f64; 3]> pulp::WithSimd for Batch<'_, '_, T, F, G> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        self.run()
    }
}

impl<T, F: Fn(&T) -> [f32; 3], G: Fn(usize) -> [f64; 3]> Batch<'_, '_, T, F, G> {
    /// Block by block: the matrix rows give each channel's share of its full light,
    /// divided by the gains where there are some, the share its table entry
    /// ([`code_index`]), and the tables the codes: one load a channel.
    #[inline(always)]
    fn run(self) {
        let BatchInverse {
            rows,
            black,
            tables,
        } = *self.inverse;
        let share = |x: &T, r: &[f32; 3]| {
            let x = (self.to_f32)(x);
            r[0] * (x[0] - black[0]) + r[1] * (x[1] - black[1]) + r[2] * (x[2] - black[2])
        };
        let [t0, t1, t2] = tables.map(|t| &*t.codes);
        let (mut shares, mut index) = ([[0f32; BLOCK]; 3], [[0u32; BLOCK]; 3]);
        let blocks = self.xyz.chunks(BLOCK).zip(self.out.chunks_mut(BLOCK));
        for (b, (block, codes)) in blocks.enumerate() {
            match &self.gains {
                // A uniform screen's gains are 1: the table entries at once.
                None => {
                    for (j, x) in block.iter().enumerate() {
                        for (entries, r) in index.iter_mut().zip(&rows) {
                            entries[j] = code_index(share(x, r));
                        }
                    }
                }
                Some(gains) => {
                    for (j, x) in block.iter().enumerate() {
                        let g = gains(b * BLOCK + j);
                        for c in 0..3 {
                            // A channel with no gain there gives no light: black, as
                            // `drive_for` gives (not the ±∞ of a division by 0).
                            shares[c][j] = match g[c] as f32 {
                                g if g > 0.0 => share(x, &rows[c]) / g,
                                _ => 0.0,
                            };
                        }
                    }
                    for (entries, channel) in index.iter_mut().zip(&shares) {
                        for (i, s) in entries.iter_mut().zip(channel) {
                            *i = code_index(*s);
                        }
                    }
                }
            }
            // An index is below the table's size by its mask: no bounds check.
            let at = |c: usize, j: usize| index[c][j] as usize & (CODE_TABLE_SIZE - 1);
            let pixel = |j: usize| [t0[at(0, j)], t1[at(1, j)], t2[at(2, j)]];
            // As many codes as colours (`zip` stops at the shorter).
            let n = block.len().min(codes.len());
            let codes = &mut codes[..n];
            // Four pixels' twelve codes as three 64-bit words, each written by one
            // store (the compiler merges the four 16-bit parts of a word), instead of
            // a store a code.
            let groups = codes.as_flattened_mut().chunks_exact_mut(12);
            let mut j = 0;
            for group in groups {
                let [r0, g0, b0] = pixel(j);
                let [r1, g1, b1] = pixel(j + 1);
                let [r2, g2, b2] = pixel(j + 2);
                let [r3, g3, b3] = pixel(j + 3);
                for (part, word) in group.chunks_exact_mut(4).zip([
                    [r0, g0, b0, r1],
                    [g1, b1, r2, g2],
                    [b2, r3, g3, b3],
                ]) {
                    part.copy_from_slice(&word);
                }
                j += 4;
            }
            for (k, code) in codes.iter_mut().enumerate().skip(j) {
                *code = pixel(k);
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use chromacal_model::transfer::{Cowan, GainOffsetGamma, Power};

    /// A law of each kind the tables must follow: a power, a cut-off, a Cowan toe.
    pub(crate) fn laws() -> [TransferLaw; 3] {
        [
            TransferLaw::Power(Power { gamma: 2.2 }),
            TransferLaw::GainOffsetGamma(GainOffsetGamma::from_cutoff(0.05, 2.4)),
            TransferLaw::Cowan(Cowan {
                a: 2.3,
                b: 0.06,
                toe: 1.0 / 255.0,
            }),
        ]
    }

    #[test]
    fn the_table_follows_the_exact_inverse() {
        for law in laws() {
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
