//! The video LUT: a CRTC's gamma ramp (RandR 1.2 `RRGetCrtcGamma`/`RRSetCrtcGamma`),
//! three tables of 16-bit outputs, one entry per input code of the ramp's size.
//!
//! Calibration curves are stored at 256 inputs; a ramp of another size (1024 on many
//! cards, 4096 on some) is filled by interpolating them at i/(N − 1), the same
//! interpolation the `.cal` and `vcgt` exports use, so the card and a file written
//! for another tool hold the same curves.

use serde::{Deserialize, Serialize};
use x11rb::protocol::randr::ConnectionExt as _;

use super::{OutputInfo, X11Error, XDisplay};
use chromacal_model::target::CalibrationCurves;

/// A gamma ramp: R, G, B tables of equal length, 0..=65535.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct GammaRamp {
    pub red: Vec<u16>,
    pub green: Vec<u16>,
    pub blue: Vec<u16>,
}

impl GammaRamp {
    /// The straight ramp of `size` entries: output = input.
    pub fn identity(size: usize) -> Self {
        Self::from_fn(size, |_, x| x)
    }

    /// A ramp from a function of channel and input in [0, 1], giving output in [0, 1].
    pub fn from_fn(size: usize, f: impl Fn(usize, f64) -> f64) -> Self {
        let last = size.saturating_sub(1).max(1) as f64;
        let table = |c: usize| -> Vec<u16> {
            (0..size)
                .map(|i| {
                    let out = f(c, i as f64 / last);
                    (out.clamp(0.0, 1.0) * 65535.0).round() as u16
                })
                .collect()
        };
        GammaRamp {
            red: table(0),
            green: table(1),
            blue: table(2),
        }
    }

    /// `curves` sampled at the ramp's `size` inputs.
    pub fn from_curves(curves: &CalibrationCurves, size: usize) -> Self {
        Self::from_fn(size, |c, x| curves.apply([x; 3])[c])
    }

    pub fn len(&self) -> usize {
        self.red.len()
    }

    pub fn is_empty(&self) -> bool {
        self.red.is_empty()
    }

    pub fn channels(&self) -> [&[u16]; 3] {
        [&self.red, &self.green, &self.blue]
    }

    /// The output in [0, 1] of `channel` for `input` in [0, 1], linearly between
    /// entries: what a card with this ramp sends for a code.
    pub fn output(&self, channel: usize, input: f64) -> f64 {
        let table = self.channels()[channel.min(2)];
        match table.len() {
            0 => input.clamp(0.0, 1.0),
            1 => f64::from(table[0]) / 65535.0,
            n => {
                let position = input.clamp(0.0, 1.0) * (n - 1) as f64;
                let i = (position.floor() as usize).min(n - 2);
                let t = position - i as f64;
                (f64::from(table[i]) * (1.0 - t) + f64::from(table[i + 1]) * t) / 65535.0
            }
        }
    }

    /// The largest difference from `other` in 16-bit steps (after resampling `other`
    /// onto this ramp's inputs when the sizes differ).
    pub fn max_difference(&self, other: &GammaRamp) -> f64 {
        let n = self.len();
        let last = n.saturating_sub(1).max(1) as f64;
        let mut worst: f64 = 0.0;
        for (c, table) in self.channels().iter().enumerate() {
            for (i, &v) in table.iter().enumerate() {
                let theirs = other.output(c, i as f64 / last) * 65535.0;
                worst = worst.max((f64::from(v) - theirs).abs());
            }
        }
        worst
    }

    /// Whether this is a straight ramp within one 16-bit step (a ramp some drivers
    /// round a little differently): i·65535/(n − 1), or i·65536/n, the code shifted up
    /// (i << 8 at 256 entries), which is what the X server loads when it starts, and
    /// whose top entry is 255 steps short of full.
    pub fn is_identity(&self) -> bool {
        let n = self.len().max(2);
        let shifted = |table: &[u16]| {
            table
                .iter()
                .enumerate()
                .all(|(i, &v)| (f64::from(v) - i as f64 * 65536.0 / n as f64).abs() <= 1.0)
        };
        self.max_difference(&GammaRamp::identity(n)) <= 1.0
            || self.channels().iter().all(|table| shifted(table))
    }

    /// The ramp as three curves of `entries` points in [0, 1] (for a `.cal` file).
    pub fn curves(&self, entries: usize) -> [Vec<f64>; 3] {
        let last = entries.saturating_sub(1).max(1) as f64;
        [0, 1, 2].map(|c| {
            (0..entries)
                .map(|i| self.output(c, i as f64 / last))
                .collect()
        })
    }
}

impl XDisplay {
    /// The gamma ramp of `output`'s CRTC.
    pub fn gamma(&self, output: &OutputInfo) -> Result<GammaRamp, X11Error> {
        let crtc = output.lit_crtc()?;
        let reply = self
            .conn
            .randr_get_crtc_gamma(crtc)
            .map_err(|e| self.protocol(e))?
            .reply()
            .map_err(|e| self.protocol(e))?;
        Ok(GammaRamp {
            red: reply.red,
            green: reply.green,
            blue: reply.blue,
        })
    }

    /// Load `ramp` into `output`'s CRTC, resampled to the size the CRTC takes, and
    /// wait until the server has it.
    pub fn set_gamma(&self, output: &OutputInfo, ramp: &GammaRamp) -> Result<(), X11Error> {
        let crtc = output.lit_crtc()?;
        let size = output.gamma_size;
        if size < 2 {
            return Err(X11Error::NoGamma {
                output: output.name.clone(),
                size,
            });
        }
        let fitted = if ramp.channels().iter().all(|c| c.len() == size) {
            ramp.clone()
        } else {
            GammaRamp::from_fn(size, |c, x| ramp.output(c, x))
        };
        self.conn
            .randr_set_crtc_gamma(crtc, &fitted.red, &fitted.green, &fitted.blue)
            .map_err(|e| self.protocol(e))?
            .check()
            .map_err(|e| self.protocol(e))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_ramps_of_any_size_are_straight() {
        for n in [2, 256, 1024, 4096] {
            let r = GammaRamp::identity(n);
            assert_eq!(r.red[0], 0);
            assert_eq!(r.blue[n - 1], 65535);
            assert!(r.is_identity());
            assert!((r.output(1, 0.5) - 0.5).abs() < 1e-4);
        }
        let mut bent = GammaRamp::identity(256);
        bent.green[128] += 300;
        assert!(!bent.is_identity());
        // The X server's ramp when nothing has loaded one: the code shifted up.
        for n in [256usize, 1024] {
            let shift = 16 - n.trailing_zeros();
            let mut server = GammaRamp::from_fn(n, |_, _| 0.0);
            for table in [&mut server.red, &mut server.green, &mut server.blue] {
                for (i, v) in table.iter_mut().enumerate() {
                    *v = (i << shift) as u16;
                }
            }
            assert!(server.is_identity(), "{n}");
            server.red[n / 2] += 200;
            assert!(!server.is_identity(), "{n}");
        }
        assert!((bent.max_difference(&GammaRamp::identity(1024)) - 300.0).abs() < 2.0);
    }

    #[test]
    fn resampling_keeps_a_curve() {
        let gamma = GammaRamp::from_fn(256, |_, x| x.powf(1.0 / 2.2));
        let big = GammaRamp::from_fn(4096, |c, x| gamma.output(c, x));
        // Between the 256 knots, linear interpolation of a 1/2.2 power law is off by
        // at most a few tenths of a percent away from black.
        for k in 1..100 {
            let x = k as f64 / 100.0;
            assert!((big.output(0, x) - gamma.output(0, x)).abs() < 2e-5, "{x}");
        }
        assert_eq!(big.curves(256)[2].len(), 256);
    }
}
