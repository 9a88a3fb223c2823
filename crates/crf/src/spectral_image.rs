//! A spectral image: a directory of single-channel Portable Float Maps named by their
//! wavelength (`450.pfm`, `550.pfm`, …), each pixel's spectrum read across the planes.
//!
//! It is held as the planes' own 32-bit samples (4 bytes a pixel a plane) and turned
//! into XYZ one pixel at a time: a pixel's spectrum on the 5 nm grid (81 doubles) lives
//! only while it is integrated. Holding every pixel's grid spectrum instead cost 170
//! times the files (two 2048² planes, 33 MB, reached 5.7 GB). Characteristic vectors,
//! which learn their basis from the scene's spectra, learn it from an even sample of
//! at most [`BASIS_SAMPLE`] pixels.

use std::path::{Path, PathBuf};

use super::scene::{SceneError, XyzImage, read_pfm, render_budget};
use super::spectral::{MethodKind, SpectralError, SpectralMethod, onto_grid_holding_ends};
use super::spectral_file::{EXTENDED_NM, covers_required, too_narrow};
use chromacal_color::Xyz;
use chromacal_color::spectrum::Observer;

/// Pixels characteristic vectors learn their basis from, at most.
pub const BASIS_SAMPLE: usize = 4096;

/// A spectral image's planes, wavelength by wavelength.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralImage {
    pub width: usize,
    pub height: usize,
    /// Rising, nm.
    pub wavelengths: Vec<f64>,
    /// One plane a wavelength, row by row from the top.
    planes: Vec<Vec<f32>>,
}

fn format_error(path: &Path, what: String) -> SceneError {
    SceneError::Format {
        path: path.to_path_buf(),
        what,
    }
}

impl SpectralImage {
    /// Read the `<nm>.pfm` planes of `dir`, one at a time (each turned into its 32-bit
    /// samples before the next is read). All must have one size; their samples
    /// together may take at most half of [`render_budget`].
    pub fn read(dir: &Path) -> Result<SpectralImage, SceneError> {
        let budget = render_budget();
        let entries = std::fs::read_dir(dir).map_err(|source| SceneError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let mut named: Vec<(f64, PathBuf)> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("pfm")))
            .filter_map(|p| {
                let nm = p.file_stem()?.to_str()?.parse::<f64>().ok()?;
                Some((nm, p))
            })
            .collect();
        named.sort_by(|a, b| a.0.total_cmp(&b.0));
        if named.len() < 2 {
            return Err(format_error(
                dir,
                "a spectral image needs at least two planes named by wavelength (e.g. 450.pfm, 550.pfm)".into(),
            ));
        }
        if let Some(w) = named.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(format_error(
                &w[1].1,
                format!("a second plane of {} nm", w[1].0),
            ));
        }
        // The rule of every spectral input (`spectral_file`): 400–700 nm covered.
        let (from, to) = (named[0].0, named[named.len() - 1].0);
        if !covers_required(from, to) {
            return Err(format_error(dir, too_narrow(from, to)));
        }
        let grey = Xyz::new(1.0, 1.0, 1.0);
        let mut image = SpectralImage {
            width: 0,
            height: 0,
            wavelengths: Vec::with_capacity(named.len()),
            planes: Vec::with_capacity(named.len()),
        };
        for (nm, path) in &named {
            let plane: XyzImage = read_pfm(path, &grey)?;
            if image.planes.is_empty() {
                (image.width, image.height) = (plane.width, plane.height);
                let bytes = named
                    .len()
                    .saturating_mul(plane.xyz.len())
                    .saturating_mul(4);
                if bytes > budget / 2 {
                    return Err(format_error(
                        dir,
                        format!(
                            "{} planes of {} × {} take {:.1} GB: at most {:.1} GB",
                            named.len(),
                            plane.width,
                            plane.height,
                            bytes as f64 / 1e9,
                            (budget / 2) as f64 / 1e9
                        ),
                    ));
                }
            } else if (plane.width, plane.height) != (image.width, image.height) {
                return Err(format_error(
                    path,
                    format!(
                        "{} × {} where the first plane is {} × {}",
                        plane.width, plane.height, image.width, image.height
                    ),
                ));
            }
            image.wavelengths.push(*nm);
            image
                .planes
                .push(plane.xyz.iter().map(|c| c.y as f32).collect());
        }
        Ok(image)
    }

    /// Pixels, row by row from the top.
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// Pixel `k`'s spectrum on the 5 nm grid: linear between planes, the nearest
    /// plane's value beyond them (380–780 nm, as `spectral_file` extends a file).
    pub fn spectrum(&self, k: usize) -> Vec<f64> {
        let values: Vec<f64> = self.planes.iter().map(|p| f64::from(p[k])).collect();
        onto_grid_holding_ends(&self.wavelengths, &values)
    }

    /// What the reader did beyond reading, for the user: `None` when the planes
    /// reach 380 and 780 nm themselves.
    pub fn warning(&self) -> Option<String> {
        let (from, to) = (
            self.wavelengths[0],
            self.wavelengths[self.wavelengths.len() - 1],
        );
        (from > EXTENDED_NM.0 || to < EXTENDED_NM.1).then(|| {
            format!(
                "the planes cover {from} to {to} nm; extended to {} to {} nm by repeating the nearest measured value",
                EXTENDED_NM.0, EXTENDED_NM.1
            )
        })
    }

    /// Every pixel's XYZ (in units of ∫ S f dλ) by `kind`, one pixel at a time.
    pub fn integrate(&self, kind: &MethodKind) -> Result<XyzImage, SpectralError> {
        let step = self.pixels().div_ceil(BASIS_SAMPLE).max(1);
        let sample: Vec<Vec<f64>> = (0..self.pixels())
            .step_by(step)
            .map(|k| self.spectrum(k))
            .collect();
        let method = SpectralMethod::new(kind.clone(), Observer::default(), &sample)?;
        drop(sample);
        let xyz = (0..self.pixels())
            .map(|k| method.integrate(&method.represent(&self.spectrum(k))))
            .collect();
        Ok(XyzImage {
            width: self.width,
            height: self.height,
            xyz,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::write_pfm;

    fn plane(dir: &Path, nm: u32, values: &[f64], width: usize) {
        let image = XyzImage {
            width,
            height: values.len() / width,
            xyz: values.iter().map(|v| Xyz::new(*v, *v, *v)).collect(),
        };
        write_pfm(&dir.join(format!("{nm}.pfm")), &image).unwrap();
    }

    #[test]
    fn pixels_are_integrated_as_their_spectra_would_be_one_by_one() {
        let dir = tempfile::tempdir().unwrap();
        plane(dir.path(), 400, &[1.0, 0.0, 0.5, 0.2], 2);
        plane(dir.path(), 700, &[0.0, 1.0, 0.5, 0.9], 2);
        let image = SpectralImage::read(dir.path()).unwrap();
        assert_eq!((image.width, image.height), (2, 2));
        assert_eq!(image.wavelengths, [400.0, 700.0]);
        // Beyond the planes, the nearest plane's value (not zero).
        let s = image.spectrum(1);
        assert_eq!((s[0], s[s.len() - 1]), (0.0, 1.0));
        assert!(image.warning().unwrap().contains("400 to 700 nm"));
        let xyz = image.integrate(&MethodKind::Direct).unwrap();
        let direct = SpectralMethod::new(MethodKind::Direct, Observer::default(), &[]).unwrap();
        for k in 0..4 {
            let expected = direct.integrate(&direct.represent(&image.spectrum(k)));
            assert_eq!(xyz.xyz[k], expected);
        }
        // Light at the blue end alone is bluish, at the red end reddish.
        assert!(xyz.xyz[0].z > xyz.xyz[0].x && xyz.xyz[1].x > xyz.xyz[1].z);
    }

    #[test]
    fn planes_of_another_size_or_a_lone_plane_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        plane(dir.path(), 400, &[1.0, 0.0], 2);
        let e = SpectralImage::read(dir.path()).unwrap_err().to_string();
        assert!(e.contains("at least two planes"), "{e}");
        // Two planes that stop short of 400–700 nm: the spectral files' sentence.
        plane(dir.path(), 650, &[1.0, 0.0], 2);
        let e = SpectralImage::read(dir.path()).unwrap_err().to_string();
        assert!(e.contains(&too_narrow(400.0, 650.0)), "{e}");
        plane(dir.path(), 700, &[1.0, 0.0, 1.0, 0.0], 2);
        let e = SpectralImage::read(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("700.pfm") && e.contains("2 × 2 where the first plane is 2 × 1"),
            "{e}"
        );
    }
}
