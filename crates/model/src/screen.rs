//! What a screen shows: integer code values at a bit depth, the window a patch fills,
//! and the content (patch and background) a display puts up. Plain data, below the
//! simulated monitor, the instruments' emulators and the display sinks, which all
//! speak of it.

use serde::{Deserialize, Serialize};

use crate::{Drive, ScreenPosition};

/// A rectangle on the screen in fractions of its width and height, from the top left.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Geometry {
    pub x: f64,
    pub y: f64,
    pub width: f64,
    pub height: f64,
}

impl Geometry {
    /// A square-ish window of `size` (fraction of each side) at the centre.
    pub fn centred(size: f64) -> Self {
        Geometry::around(ScreenPosition::CENTRE, size)
    }

    /// A window of `size` centred on `centre`, kept on the screen.
    pub fn around(centre: ScreenPosition, size: f64) -> Self {
        let size = size.clamp(0.0, 1.0);
        Geometry {
            x: (centre.x - size / 2.0).clamp(0.0, 1.0 - size),
            y: (centre.y - size / 2.0).clamp(0.0, 1.0 - size),
            width: size,
            height: size,
        }
    }

    pub fn centre(&self) -> ScreenPosition {
        ScreenPosition::new(self.x + self.width / 2.0, self.y + self.height / 2.0)
    }

    pub fn area(&self) -> f64 {
        self.width * self.height
    }

    pub fn contains(&self, p: ScreenPosition) -> bool {
        p.x >= self.x && p.x <= self.x + self.width && p.y >= self.y && p.y <= self.y + self.height
    }
}

impl Default for Geometry {
    fn default() -> Self {
        Geometry::centred(0.2)
    }
}

/// What the screen shows: a patch in a window on a background.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct ScreenContent {
    pub patch: Drive,
    pub background: Drive,
    pub geometry: Geometry,
}

/// A patch as sent to a display: integer code values at a bit depth.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Codes {
    pub rgb: [u32; 3],
    pub bit_depth: u32,
}

impl Codes {
    /// The largest code at this depth.
    pub fn max(bit_depth: u32) -> u32 {
        (1u32 << bit_depth) - 1
    }

    /// The nearest codes to a normalised drive.
    pub fn from_drive(drive: Drive, bit_depth: u32) -> Self {
        let max = Self::max(bit_depth) as f64;
        Codes {
            rgb: drive.map(|d| (d.clamp(0.0, 1.0) * max).round() as u32),
            bit_depth,
        }
    }

    /// Normalised drive, each channel in [0, 1].
    pub fn drive(&self) -> Drive {
        let max = Self::max(self.bit_depth) as f64;
        self.rgb.map(|c| c as f64 / max)
    }
}

/// One patch to show.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Patch {
    pub codes: Codes,
    pub background: Codes,
    pub geometry: Geometry,
}

impl Patch {
    pub fn content(&self) -> ScreenContent {
        ScreenContent {
            patch: self.codes.drive(),
            background: self.background.drive(),
            geometry: self.geometry,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_geometry_stays_on_screen() {
        let c = Codes::from_drive([0.5, 1.0, 0.0], 8);
        assert_eq!(c.rgb, [128, 255, 0]);
        assert_eq!(Codes::from_drive(c.drive(), 8), c);
        let g = Geometry::around(ScreenPosition::new(0.0, 1.0), 0.2);
        assert_eq!((g.x, g.y), (0.0, 0.8));
        assert!(g.contains(g.centre()));
        assert!(!g.contains(ScreenPosition::CENTRE));
    }
}
