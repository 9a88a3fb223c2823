//! The patch sequence of a calibration.
//!
//! The *budget* counts the patches the model is fitted on, the quality checks that
//! cost patches, and the drift reference: black, per-channel ramps spaced evenly in
//! lightness, greys for additivity, a surround pair for spatial independence, and the
//! repeats of the reference white. Two sets are planned on top of it and reported
//! apart: the *verification* set, held out of every fit so its error is honest, and
//! the *uniformity grid* that measures the spatial map.
//!
//! The order is shuffled (seeded) so that drift does not line up with level, and the
//! reference white is shown at the start, at the end and evenly in between.

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::measurement::Role;
use crate::screen::{Codes, Geometry, Patch};
use crate::{Drive, ScreenPosition};
use chromacal_color::ictcp::pq_inverse_eotf;
use chromacal_color::spaces::lightness_to_luminance;

/// Nominal gamma used only to space the ramp levels before anything is measured.
const NOMINAL_GAMMA: f64 = 2.2;

/// The `[plan]` section of the config.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlanConfig {
    /// Patches for fitting, checks and drift (see the module documentation).
    pub budget: usize,
    /// Held-out verification patches, on top of the budget.
    pub verification: usize,
    /// Uniformity grid of n × n positions (0 or 1: none), on top of the budget.
    pub uniformity_grid: usize,
    /// Measure R, G and B (not only white) at each grid position, so that a spatial
    /// map per channel can be tried.
    pub uniformity_per_channel: bool,
    /// Bit depth of the code values sent to the display.
    pub bit_depth: u32,
    /// Patch size as a fraction of the screen's width and height.
    pub patch_size: f64,
    /// Seed of the patch order and of the verification set.
    pub seed: u64,
    /// `fixed`: every patch planned before the run; `sequential`: a seed plan of
    /// `seed_budget` patches, then each next patch where the model is least sure, until
    /// the estimated held-out error meets `target_de00` or `budget` is spent.
    pub strategy: Strategy,
    /// Counted patches of a sequential run's seed plan.
    pub seed_budget: usize,
    /// A sequential run stops when its estimated held-out mean ΔE00 is at most this.
    pub target_de00: f64,
    /// The signal the codes are: SDR (the display's own response), or an HDR signal
    /// the display decodes (PQ or HLG, BT.2020 primaries). Unset: the target's tone
    /// says (`pq` or `hlg`), else SDR. Kept in the journal and the profile.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub signal: Option<Signal>,
    /// Measure white and a grey as windows of 1 to 100 % of the screen at the end of
    /// the plan (`WINDOW_AREAS`), for the brightness limiter. Unset: on for HDR
    /// signals, off for SDR.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub brightness_limiter: Option<bool>,
}

/// The windows' shares of the screen's area the brightness-limiter patches are
/// shown at: the sizes HDR reviews and calibration tools measure peak brightness at,
/// and 75 %, so that a limiter which binds only near a full field (an LCD's) is seen
/// at two sizes and can be cross-validated.
pub const WINDOW_AREAS: [f64; 9] = [0.01, 0.02, 0.05, 0.10, 0.18, 0.25, 0.50, 0.75, 1.0];

/// The grey the brightness-limiter patches measure beside white: on a PQ signal
/// about 200 cd/m² (BT.2408's reference white, 203), on SDR above mid-grey.
pub const WINDOW_GREY: f64 = 0.58;

/// What the codes sent to the display mean.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Signal {
    /// The display's own response (an SDR mode).
    #[default]
    Sdr,
    /// SMPTE ST 2084 (BT.2100 PQ) with BT.2020 primaries: absolute luminance.
    Pq,
    /// BT.2100 Hybrid Log-Gamma with BT.2020 primaries.
    Hlg,
}

impl Signal {
    pub fn is_hdr(self) -> bool {
        self != Signal::Sdr
    }

    /// The signal's name in a config (`plan.signal`).
    pub fn name(self) -> &'static str {
        match self {
            Signal::Sdr => "sdr",
            Signal::Pq => "pq",
            Signal::Hlg => "hlg",
        }
    }

    /// How the signal is named where a run is described.
    pub fn describe(self) -> &'static str {
        match self {
            Signal::Sdr => "SDR",
            Signal::Pq => "PQ (SMPTE ST 2084), BT.2020 primaries",
            Signal::Hlg => "HLG (BT.2100), BT.2020 primaries",
        }
    }
}

/// How the patches of a run are chosen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Strategy {
    #[default]
    Fixed,
    Sequential,
}

/// The limits of a sequential run, kept in its plan (and so in its journal's header).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SequentialLimits {
    /// Most counted patches, the seed plan's included.
    pub budget: usize,
    pub target_de00: f64,
}

impl Default for PlanConfig {
    fn default() -> Self {
        PlanConfig {
            budget: 40,
            verification: 12,
            uniformity_grid: 3,
            uniformity_per_channel: false,
            bit_depth: 8,
            patch_size: 0.2,
            seed: 7,
            strategy: Strategy::Sequential,
            seed_budget: 20,
            target_de00: 0.2,
            signal: None,
            brightness_limiter: None,
        }
    }
}

/// Why no plan could be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    #[error(
        "a budget of {budget} patches is too small: the least is {minimum} (black, two reference whites and two levels per channel)"
    )]
    BudgetTooSmall { budget: usize, minimum: usize },
    #[error("bit depth {0} is not supported (1 to 16)")]
    BitDepth(u32),
    #[error("patch size {0} must be in (0, 1]")]
    PatchSize(f64),
    #[error("plan.uniformity_grid is below 2: there is no grid to measure")]
    NoGrid,
    #[error(
        "plan.seed_budget ({seed}) is above plan.budget ({budget}): the seed plan is part of the budget"
    )]
    SeedAboveBudget { seed: usize, budget: usize },
    #[error("plan.target_de00 must be a number of at least 0, not {0}")]
    Target(f64),
}

/// One patch of the plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlannedPatch {
    /// Position in the sequence.
    pub index: usize,
    pub role: Role,
    pub patch: Patch,
}

impl PlannedPatch {
    /// Where the instrument reads this patch.
    pub fn position(&self) -> ScreenPosition {
        self.patch.geometry.centre()
    }
}

/// How the budget was spent.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct BudgetBreakdown {
    pub black: usize,
    pub ramp_levels_per_channel: usize,
    pub grey: usize,
    pub surround: usize,
    pub reference: usize,
    /// Everything above: the "measured patches" a calibration's accuracy is quoted with.
    pub counted: usize,
    pub verification: usize,
    pub uniformity: usize,
    /// White and a grey at each of `WINDOW_AREAS`, for the brightness limiter (0 in
    /// plans made before there were any).
    #[serde(default)]
    pub window: usize,
}

/// The patch sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    pub patches: Vec<PlannedPatch>,
    pub budget: BudgetBreakdown,
    /// Set for a sequential run: `patches` is its seed plan, and the journal may hold
    /// patches beyond it, numbered on from its end (`calibrate::sequential`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequential: Option<SequentialLimits>,
    /// The HDR signal the codes are (PQ, HLG); absent for SDR.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub signal: Option<Signal>,
}

/// Drive levels for `n` ramp steps, evenly spaced in CIE L* of a nominal
/// E = v^2.2 channel from L* = 50/n to full drive, as distinct codes.
pub fn ramp_levels(n: usize, bit_depth: u32) -> Vec<u32> {
    let max = Codes::max(bit_depth);
    // L* from half a step above black to 100: the dimmest level sits low enough to
    // pin down the toe of the curve, where dark colours are most sensitive.
    let lowest = 50.0 / n as f64;
    let mut codes: Vec<u32> = (1..=n)
        .map(|k| {
            let l_star = if n == 1 {
                100.0
            } else {
                lowest + (100.0 - lowest) * (k - 1) as f64 / (n - 1) as f64
            };
            let v = lightness_to_luminance(l_star).powf(1.0 / NOMINAL_GAMMA);
            ((v * max as f64).round() as u32).max(1)
        })
        .collect();
    codes.dedup();
    codes
}

/// Radical inverse of `i` in `base`: the Halton sequence (Halton 1960).
fn halton(mut i: usize, base: usize) -> f64 {
    let mut f = 1.0;
    let mut r = 0.0;
    while i > 0 {
        f /= base as f64;
        r += f * (i % base) as f64;
        i /= base;
    }
    r
}

/// Held-out drives: three quarters spread through the RGB cube (a scrambled Halton
/// sequence), one quarter near the grey axis, where errors show most.
pub fn verification_drives(n: usize, seed: u64) -> Vec<Drive> {
    let offset = (seed % 997) as usize + 20;
    let near_grey = n / 4;
    let mut drives = Vec::with_capacity(n);
    for i in 0..n - near_grey {
        let k = i + offset;
        drives.push([halton(k, 2), halton(k, 3), halton(k, 5)]);
    }
    for i in 0..near_grey {
        let k = i + offset;
        let level = 0.05 + 0.9 * halton(k, 7);
        let tint = |b: usize| (halton(k, b) - 0.5) * 0.08;
        drives.push([
            (level + tint(11)).clamp(0.0, 1.0),
            (level + tint(13)).clamp(0.0, 1.0),
            (level + tint(17)).clamp(0.0, 1.0),
        ]);
    }
    drives
}

/// The uniformity grid of `config`: white (or R, G and B) at each n × n position but
/// the centre, which the rest of the plan measures.
fn uniformity_patches(config: &PlanConfig) -> Vec<(Role, Patch)> {
    let mut patches = Vec::new();
    if config.uniformity_grid < 2 {
        return patches;
    }
    let n = config.uniformity_grid;
    let depth = config.bit_depth;
    let size = config.patch_size.min(1.0 / n as f64);
    let drives: Vec<Drive> = if config.uniformity_per_channel {
        vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    } else {
        vec![[1.0; 3]]
    };
    for i in 0..n {
        for j in 0..n {
            let p = ScreenPosition::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
            if p.is_centre() {
                continue;
            }
            for d in &drives {
                patches.push((
                    Role::Uniformity,
                    Patch {
                        codes: Codes::from_drive(*d, depth),
                        background: Codes::from_drive([0.0; 3], depth),
                        geometry: Geometry::around(p, size),
                    },
                ));
            }
        }
    }
    patches
}

/// Number the patches of a short plan in order.
fn numbered(patches: Vec<(Role, Patch)>) -> Vec<PlannedPatch> {
    patches
        .into_iter()
        .enumerate()
        .map(|(index, (role, patch))| PlannedPatch { index, role, patch })
        .collect()
}

/// A verification: `n` patches (at least 5) to compare with what the current profile
/// predicts: white, the three primaries, a mid grey, then held-out-style drives. The
/// set depends only on `config` and `n`, so verifications over weeks compare alike.
pub fn make_verification_plan(config: &PlanConfig, n: usize) -> Result<Plan, PlanError> {
    if !(1..=16).contains(&config.bit_depth) {
        return Err(PlanError::BitDepth(config.bit_depth));
    }
    if !(config.patch_size > 0.0 && config.patch_size <= 1.0) {
        return Err(PlanError::PatchSize(config.patch_size));
    }
    let depth = config.bit_depth;
    let centre = Geometry::centred(config.patch_size);
    let mut drives: Vec<Drive> = vec![
        [1.0; 3],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.5; 3],
    ];
    drives.extend(verification_drives(n.saturating_sub(5), config.seed));
    let patches = drives
        .into_iter()
        .map(|d| {
            (
                Role::Verification,
                Patch {
                    codes: Codes::from_drive(d, depth),
                    background: Codes::from_drive([0.0; 3], depth),
                    geometry: centre,
                },
            )
        })
        .collect();
    let patches = numbered(patches);
    let verification = patches.len();
    Ok(Plan {
        signal: None,
        sequential: None,
        patches,
        budget: BudgetBreakdown {
            black: 0,
            ramp_levels_per_channel: 0,
            grey: 0,
            surround: 0,
            reference: 0,
            counted: 0,
            verification,
            uniformity: 0,
            window: 0,
        },
    })
}

/// A uniformity measurement on its own: the grid of `config`, with a white reference
/// at the centre before, between every `n` positions and after, so that a change of
/// the whole screen since the calibration is told apart from the map.
pub fn make_uniformity_plan(config: &PlanConfig) -> Result<Plan, PlanError> {
    if config.uniformity_grid < 2 {
        return Err(PlanError::NoGrid);
    }
    let centre = Geometry::centred(config.patch_size);
    let white = Codes::from_drive([1.0; 3], config.bit_depth);
    let reference = (
        Role::Reference,
        Patch {
            codes: white,
            background: Codes::from_drive([0.0; 3], config.bit_depth),
            geometry: centre,
        },
    );
    let grid = uniformity_patches(config);
    let uniformity = grid.len();
    let mut patches = vec![reference];
    for chunk in grid.chunks(config.uniformity_grid.max(2)) {
        patches.extend_from_slice(chunk);
        patches.push(reference);
    }
    let references = patches.len() - uniformity;
    Ok(Plan {
        signal: None,
        sequential: None,
        patches: numbered(patches),
        budget: BudgetBreakdown {
            black: 0,
            ramp_levels_per_channel: 0,
            grey: 0,
            surround: 0,
            reference: references,
            counted: references,
            verification: 0,
            uniformity,
            window: 0,
        },
    })
}

/// Build the patch sequence for `config`: all of it for a fixed plan, the seed plan
/// for a sequential one.
pub fn make_plan(config: &PlanConfig) -> Result<Plan, PlanError> {
    let mut plan = make_plan_of_strategy(config)?;
    let signal = config.signal.filter(|s| s.is_hdr());
    plan.signal = signal;
    if signal == Some(Signal::Pq) {
        add_knee_ramps(&mut plan, config.bit_depth);
    }
    if config.brightness_limiter.unwrap_or(signal.is_some()) {
        let windows = window_patches(config.bit_depth);
        plan.budget.window = windows.len();
        let start = plan.patches.len();
        plan.patches
            .extend(
                windows
                    .into_iter()
                    .enumerate()
                    .map(|(k, (role, patch))| PlannedPatch {
                        index: start + k,
                        role,
                        patch,
                    }),
            );
    }
    Ok(plan)
}

/// Luminances (cd/m²) about which HDR displays reach their peak (most between 400 and
/// 2,000). A display decoding PQ clips or rolls off there, and the PQ law's choice
/// between the two needs each channel read on both sides of its knee, which ramp
/// levels spread over the whole code range leave out (four levels put none between
/// 0.67 and full drive: a run then took a clip at 835 cd/m² for a roll-off to 800,
/// 6 % too bright at drive 0.72).
pub const PQ_KNEE_LUMINANCES: [f64; 3] = [600.0, 1000.0, 2000.0];

/// Each channel's ramp read at the PQ codes of `PQ_KNEE_LUMINANCES` (those the plan
/// does not read already), as counted ramp patches of the plan's own geometry.
fn add_knee_ramps(plan: &mut Plan, depth: u32) {
    let Some(template) = plan
        .patches
        .iter()
        .find(|p| p.role == Role::Ramp)
        .map(|p| p.patch)
    else {
        return;
    };
    let top = f64::from((1u32 << depth) - 1);
    let mut added: Vec<Patch> = Vec::new();
    for c in 0..3 {
        for nits in PQ_KNEE_LUMINANCES {
            let mut rgb = [0; 3];
            rgb[c] = (pq_inverse_eotf(nits) * top).round() as u32;
            let codes = Codes {
                rgb,
                bit_depth: depth,
            };
            if !plan.patches.iter().any(|p| p.patch.codes == codes) {
                added.push(Patch { codes, ..template });
            }
        }
    }
    plan.budget.counted += added.len();
    let start = plan.patches.len();
    plan.patches.extend(
        added
            .into_iter()
            .enumerate()
            .map(|(k, patch)| PlannedPatch {
                index: start + k,
                role: Role::Ramp,
                patch,
            }),
    );
}

/// White and `WINDOW_GREY` at each of `WINDOW_AREAS`, centred on black, largest
/// first: the run ends on the smallest window, so that what is measured next does
/// not wait for a limiter held down by a full field.
fn window_patches(depth: u32) -> Vec<(Role, Patch)> {
    WINDOW_AREAS
        .iter()
        .rev()
        .flat_map(|area| {
            [[1.0; 3], [WINDOW_GREY; 3]].map(|drive| {
                (
                    Role::Window,
                    Patch {
                        codes: Codes::from_drive(drive, depth),
                        background: Codes::from_drive([0.0; 3], depth),
                        geometry: Geometry::centred(area.sqrt()),
                    },
                )
            })
        })
        .collect()
}

fn make_plan_of_strategy(config: &PlanConfig) -> Result<Plan, PlanError> {
    match config.strategy {
        Strategy::Fixed => make_fixed_plan(config),
        Strategy::Sequential => {
            if config.seed_budget > config.budget {
                return Err(PlanError::SeedAboveBudget {
                    seed: config.seed_budget,
                    budget: config.budget,
                });
            }
            if !(config.target_de00 >= 0.0) {
                return Err(PlanError::Target(config.target_de00));
            }
            let mut plan = make_fixed_plan(&PlanConfig {
                budget: config.seed_budget,
                ..config.clone()
            })?;
            plan.sequential = Some(SequentialLimits {
                budget: config.budget,
                target_de00: config.target_de00,
            });
            Ok(plan)
        }
    }
}

/// Build the whole patch sequence for `config`'s budget.
fn make_fixed_plan(config: &PlanConfig) -> Result<Plan, PlanError> {
    if !(1..=16).contains(&config.bit_depth) {
        return Err(PlanError::BitDepth(config.bit_depth));
    }
    if !(config.patch_size > 0.0 && config.patch_size <= 1.0) {
        return Err(PlanError::PatchSize(config.patch_size));
    }
    let minimum = 1 + 2 + 3 * 2;
    let b = config.budget;
    if b < minimum {
        return Err(PlanError::BudgetTooSmall { budget: b, minimum });
    }
    let depth = config.bit_depth;
    // From 20 patches on, every assumption the fit rests on gets its test (greys for
    // additivity, a surround pair for spatial independence, three references for
    // drift), at the cost of a second black below 24: a black reading is the slowest
    // of all (an auto-ranging instrument integrates it longest), the others are fast.
    let reference = if (20..24).contains(&b) {
        3
    } else {
        ((b as f64 / 12.0).round() as usize).max(2)
    };
    let (grey, surround) = if b >= 96 {
        (5, 2)
    } else if b >= 24 {
        (3, 2)
    } else if b >= 20 {
        (2, 2)
    } else {
        (0, 0)
    };
    let base_black = if b >= 96 {
        3
    } else if b >= 24 {
        2
    } else {
        1
    };
    let levels_wanted = (b - reference - grey - surround - base_black) / 3;
    let levels = ramp_levels(levels_wanted, depth);
    let black = b - reference - grey - surround - 3 * levels.len();

    let centre = Geometry::centred(config.patch_size);
    let black_codes = Codes::from_drive([0.0; 3], depth);
    let white_codes = Codes::from_drive([1.0; 3], depth);
    let patch = |codes: Codes, geometry: Geometry| Patch {
        codes,
        background: black_codes,
        geometry,
    };

    let mut body: Vec<(Role, Patch)> = Vec::new();
    for _ in 0..black {
        body.push((Role::Black, patch(black_codes, centre)));
    }
    for c in 0..3 {
        for code in &levels {
            let mut rgb = [0; 3];
            rgb[c] = *code;
            let codes = Codes {
                rgb,
                bit_depth: depth,
            };
            body.push((Role::Ramp, patch(codes, centre)));
        }
    }
    // Greys at ramp levels, so additivity is checked against measured channels.
    for k in 0..grey {
        let i = ((k + 1) * levels.len()) / (grey + 1);
        let code = levels[i.min(levels.len() - 1)];
        let codes = Codes {
            rgb: [code; 3],
            bit_depth: depth,
        };
        body.push((Role::Grey, patch(codes, centre)));
    }
    if surround > 0 {
        let mid = levels[levels.len() / 2];
        let codes = Codes {
            rgb: [mid; 3],
            bit_depth: depth,
        };
        let small = Geometry::centred(config.patch_size.min(0.1));
        body.push((Role::Surround, patch(codes, small)));
        body.push((
            Role::Surround,
            Patch {
                codes,
                background: white_codes,
                geometry: small,
            },
        ));
    }
    let verification = verification_drives(config.verification, config.seed);
    for d in &verification {
        body.push((
            Role::Verification,
            patch(Codes::from_drive(*d, depth), centre),
        ));
    }
    let grid = uniformity_patches(config);
    let uniformity = grid.len();
    body.extend(grid);

    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    body.shuffle(&mut rng);

    // Reference whites at the start, the end and evenly between.
    let total = body.len() + reference;
    let mut reference_slots: Vec<usize> = (0..reference)
        .map(|k| (k * (total - 1)) / (reference - 1))
        .collect();
    reference_slots.dedup();
    let mut body = body.into_iter();
    let mut patches = Vec::with_capacity(total);
    for index in 0..total {
        let (role, p) = if reference_slots.binary_search(&index).is_ok() {
            (Role::Reference, patch(white_codes, centre))
        } else {
            match body.next() {
                Some(item) => item,
                None => (Role::Reference, patch(white_codes, centre)),
            }
        };
        patches.push(PlannedPatch {
            index,
            role,
            patch: p,
        });
    }
    Ok(Plan {
        signal: None,
        sequential: None,
        patches,
        budget: BudgetBreakdown {
            black,
            ramp_levels_per_channel: levels.len(),
            grey,
            surround,
            reference,
            counted: b,
            verification: verification.len(),
            uniformity,
            window: 0,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(plan: &Plan, role: Role) -> usize {
        plan.patches.iter().filter(|p| p.role == role).count()
    }

    #[test]
    fn budgets_are_spent_exactly() {
        for budget in [9, 12, 20, 23, 24, 48, 96, 200] {
            let config = PlanConfig {
                budget,
                strategy: Strategy::Fixed,
                ..Default::default()
            };
            let plan = make_plan(&config).unwrap();
            let counted: usize = [
                Role::Black,
                Role::Ramp,
                Role::Grey,
                Role::Surround,
                Role::Reference,
            ]
            .iter()
            .map(|r| count(&plan, *r))
            .sum();
            assert_eq!(counted, budget, "budget {budget}: {:?}", plan.budget);
            assert_eq!(plan.budget.counted, budget);
            assert_eq!(count(&plan, Role::Verification), config.verification);
            let n = config.uniformity_grid;
            assert_eq!(count(&plan, Role::Uniformity), n * n - 1);
            assert!(count(&plan, Role::Black) >= 1);
            if budget >= 20 {
                // Every assumption gets its test: additivity, surround, drift.
                assert!(count(&plan, Role::Grey) >= 2, "budget {budget}");
                assert_eq!(count(&plan, Role::Surround), 2, "budget {budget}");
                assert!(count(&plan, Role::Reference) >= 2, "budget {budget}");
                assert!(plan.budget.ramp_levels_per_channel >= 4, "budget {budget}");
            }
            assert_eq!(
                count(&plan, Role::Ramp),
                3 * plan.budget.ramp_levels_per_channel
            );
            for (i, p) in plan.patches.iter().enumerate() {
                assert_eq!(p.index, i);
            }
        }
        assert!(matches!(
            make_plan(&PlanConfig {
                budget: 8,
                strategy: Strategy::Fixed,
                ..Default::default()
            }),
            Err(PlanError::BudgetTooSmall { .. })
        ));
    }

    #[test]
    fn ramps_end_at_full_drive_and_are_denser_in_the_dark() {
        let levels = ramp_levels(12, 8);
        assert_eq!(*levels.last().unwrap(), 255);
        assert!(levels.windows(2).all(|w| w[1] > w[0]));
        // Evenly spaced in L* means the first step in drive is larger than a
        // uniform 255/12 would be only near black; check spacing is not uniform.
        let steps: Vec<u32> = levels.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(steps.first() != steps.last());
        // Low bit depths drop duplicate codes rather than repeat them.
        let coarse = ramp_levels(12, 2);
        assert!(coarse.len() <= 3 && coarse.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn reference_opens_and_closes_the_run_and_order_is_seeded() {
        let plan = make_plan(&PlanConfig::default()).unwrap();
        assert_eq!(plan.patches[0].role, Role::Reference);
        assert_eq!(plan.patches.last().unwrap().role, Role::Reference);
        let again = make_plan(&PlanConfig::default()).unwrap();
        assert_eq!(plan, again);
        let other = make_plan(&PlanConfig {
            seed: 8,
            ..Default::default()
        })
        .unwrap();
        assert_ne!(plan.patches, other.patches);
    }

    #[test]
    fn grid_covers_the_screen_without_the_centre() {
        let plan = make_plan(&PlanConfig {
            uniformity_per_channel: true,
            uniformity_grid: 5,
            ..Default::default()
        })
        .unwrap();
        let cells: Vec<_> = plan
            .patches
            .iter()
            .filter(|p| p.role == Role::Uniformity)
            .collect();
        assert_eq!(cells.len(), 24 * 3);
        assert!(cells.iter().all(|p| !p.position().is_centre()));
        assert!(
            cells
                .iter()
                .any(|p| p.position().x < 0.2 && p.position().y < 0.2)
        );
    }
}
