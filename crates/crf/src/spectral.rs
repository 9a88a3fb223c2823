//! Spectra to XYZ by the survey's methods (seed §3), each with its cost counted in
//! multiplications and additions, for the two steps a spectral renderer repeats: the
//! spectrum–reflectance product (light reflected once) and the integration (spectrum
//! to XYZ).
//!
//! Every spectrum here lies on one grid, 380–780 nm every 5 nm (81 samples): the CIE's
//! weighted-ordinate grid, and that of the CIE illuminants and the ColorChecker. The
//! reference is the direct weighted-ordinate sum on that grid (seed §3.1.1, CIE 15);
//! each method represents a spectrum its own way (samples at its wavelengths,
//! polynomial coefficients, coordinates in a basis), and the costs counted are those of
//! the product and integration on that representation, as the survey counts them.
//! Making the representation from tabulated data (interpolating, projecting) is the
//! scene's preparation, done once, and is not counted.

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::Serialize;

use chromacal_color::Xyz;
use chromacal_color::spectrum::Observer;

/// First wavelength of the grid (nm).
pub const GRID_START_NM: f64 = 380.0;
/// Step of the grid (nm).
pub const GRID_STEP_NM: f64 = 5.0;
/// Samples on the grid: 380, 385, …, 780 nm.
pub const GRID_LEN: usize = 81;

/// The wavelengths a method integrates over: a stretch of the grid. chromacal uses
/// the whole grid, 380–780 nm; the survey used 380–700 nm (seed §3: λ_inf = 380 nm,
/// λ_sup = 700 nm), and `bench spectral` runs both.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Band {
    pub from_nm: f64,
    pub to_nm: f64,
}

impl Band {
    /// The whole grid, 380–780 nm.
    pub const FULL: Band = Band {
        from_nm: GRID_START_NM,
        to_nm: 780.0,
    };
    /// The survey's visible domain, 380–700 nm.
    pub const SURVEY: Band = Band {
        from_nm: 380.0,
        to_nm: 700.0,
    };

    /// Grid indices of the band's first and last samples.
    fn indices(&self) -> (usize, usize) {
        let at = |nm: f64| {
            (((nm - GRID_START_NM) / GRID_STEP_NM).round().max(0.0) as usize).min(GRID_LEN - 1)
        };
        (at(self.from_nm), at(self.to_nm))
    }

    /// The grid's samples in the band.
    fn len(&self) -> usize {
        let (a, b) = self.indices();
        b - a + 1
    }
}

/// Wavelength of grid sample `i`.
pub fn grid_nm(i: usize) -> f64 {
    GRID_START_NM + GRID_STEP_NM * i as f64
}

/// A spectrum's value at any wavelength of the grid's range, by linear interpolation
/// between grid samples (0 outside).
fn interpolate(spectrum: &[f64], nm: f64) -> f64 {
    let t = (nm - GRID_START_NM) / GRID_STEP_NM;
    if !(0.0..=(GRID_LEN - 1) as f64).contains(&t) {
        return 0.0;
    }
    let i = (t.floor() as usize).min(GRID_LEN - 2);
    let f = t - i as f64;
    spectrum[i] * (1.0 - f) + spectrum[i + 1] * f
}

/// A table on another grid, read onto the grid by linear interpolation (0 outside
/// its range, as the CMFs' sums stop there).
pub fn onto_grid(wavelengths: &[f64], values: &[f64]) -> Vec<f64> {
    (0..GRID_LEN)
        .map(|i| {
            let nm = grid_nm(i);
            let Some(k) = wavelengths
                .windows(2)
                .position(|w| w[0] <= nm && nm <= w[1])
            else {
                return 0.0;
            };
            let (a, b) = (wavelengths[k], wavelengths[k + 1]);
            let f = if b > a { (nm - a) / (b - a) } else { 0.0 };
            values[k] * (1.0 - f) + values[k + 1] * f
        })
        .collect()
}

/// The same, but holding the table's first and last values beyond its ends (the
/// nearest measured value, the extrapolation of `spectral_file`'s rule).
pub fn onto_grid_holding_ends(wavelengths: &[f64], values: &[f64]) -> Vec<f64> {
    let (Some(first), Some(last)) = (wavelengths.first(), wavelengths.last()) else {
        return vec![0.0; GRID_LEN];
    };
    let mut grid = onto_grid(wavelengths, values);
    for (i, v) in grid.iter_mut().enumerate() {
        let nm = grid_nm(i);
        if nm < *first {
            *v = values[0];
        } else if nm > *last {
            *v = values[values.len() - 1];
        }
    }
    grid
}

/// Multiplications and additions of one step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Operations {
    pub multiplications: usize,
    pub additions: usize,
}

impl Operations {
    const fn new(multiplications: usize, additions: usize) -> Self {
        Operations {
            multiplications,
            additions,
        }
    }
}

/// A method of the survey, with its parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case", tag = "method")]
pub enum MethodKind {
    /// Weighted ordinates on the whole grid (seed §3.1.1): the reference.
    Direct,
    /// Weighted ordinates at every `step_nm` (a multiple of 5) from 380 nm: point
    /// sampling at fewer, evenly spaced wavelengths (the survey's "Riemann based
    /// algorithm using less evenly spaced points").
    Sampling { step_nm: usize },
    /// Gaussian quadrature with each colour-matching function as the weight function
    /// (Wallis 1975; seed §3.1.2.1, the XYZ form of Meyer 1988's wavelength
    /// selection): `points` wavelengths and weights per function.
    Gauss { points: usize },
    /// Raso and Fournier (1991): two polynomial spans split at 550 nm, fitted by least
    /// squares, in the Chebyshev basis so that the product's degree is reduced by
    /// truncating its Chebyshev series (seed §3.3.1); the colour-matching functions
    /// are polynomials of the same form. The survey's method is cubic (`degree` 3).
    RasoFournier { degree: usize },
    /// Peercy (1993): coordinates in the first `m` characteristic vectors of a family
    /// of spectra representative of the scene; a reflectance is an m × m matrix
    /// (seed §3.3.2).
    CharacteristicVectors { m: usize },
}

impl MethodKind {
    pub fn name(&self) -> &'static str {
        match self {
            MethodKind::Direct => "direct (weighted ordinates)",
            MethodKind::Sampling { .. } => "point sampling",
            MethodKind::Gauss { .. } => "Gaussian quadrature",
            MethodKind::RasoFournier { .. } => "Raso–Fournier polynomials",
            MethodKind::CharacteristicVectors { .. } => "characteristic vectors (Peercy)",
        }
    }

    pub fn parameter(&self) -> String {
        self.parameter_in(Band::FULL)
    }

    /// The parameter as it stands over `band` (the samples a sampling method takes
    /// there).
    pub fn parameter_in(&self, band: Band) -> String {
        match self {
            MethodKind::Direct => format!("{} samples, 5 nm", band.len()),
            MethodKind::Sampling { step_nm } => {
                format!(
                    "{} samples, {step_nm} nm",
                    sampling_wavelengths(*step_nm, band).len()
                )
            }
            MethodKind::Gauss { points } => format!("{points} per function"),
            MethodKind::RasoFournier { degree } => format!("2 spans, degree {degree}"),
            MethodKind::CharacteristicVectors { m } => format!("m = {m}"),
        }
    }
}

impl std::str::FromStr for MethodKind {
    type Err = String;

    /// `direct`, `sampling:STEP_NM`, `gauss:POINTS`, `raso-fournier:DEGREE` or
    /// `cva:M`.
    fn from_str(text: &str) -> Result<Self, String> {
        let (name, parameter) = text.split_once(':').unwrap_or((text, ""));
        let number = |what: &str| -> Result<usize, String> {
            parameter.parse::<usize>().map_err(|_| {
                format!(
                    "'{text}': {name} needs {what} after a colon, e.g. {name}:{}",
                    match name {
                        "sampling" => "10",
                        "gauss" => "8",
                        "raso-fournier" => "3",
                        _ => "8",
                    }
                )
            })
        };
        match name.to_ascii_lowercase().as_str() {
            "direct" if parameter.is_empty() => Ok(MethodKind::Direct),
            "sampling" => Ok(MethodKind::Sampling {
                step_nm: number("a step in nm")?,
            }),
            "gauss" => Ok(MethodKind::Gauss {
                points: number("the points per function")?,
            }),
            "raso-fournier" => Ok(MethodKind::RasoFournier {
                degree: number("a degree")?,
            }),
            "cva" => Ok(MethodKind::CharacteristicVectors {
                m: number("the number of vectors")?,
            }),
            _ => Err(format!(
                "'{text}': the methods are direct, sampling:STEP_NM, gauss:POINTS, raso-fournier:DEGREE and cva:M"
            )),
        }
    }
}

/// Wavelengths of point sampling every `step_nm` across `band`.
fn sampling_wavelengths(step_nm: usize, band: Band) -> Vec<f64> {
    let step = step_nm.max(5);
    (0..)
        .map(|k| band.from_nm + (k * step) as f64)
        .take_while(|nm| *nm <= band.to_nm + 1e-9)
        .collect()
}

/// A spectrum as a method holds it.
#[derive(Debug, Clone, PartialEq)]
pub struct Represented(Vec<f64>);

/// A reflectance as a method multiplies by it.
#[derive(Debug, Clone, PartialEq)]
pub enum Reflectance {
    /// Values at the method's wavelengths (sampling methods).
    Samples(Vec<f64>),
    /// Chebyshev coefficients of each span (Raso–Fournier).
    Polynomial(Vec<f64>),
    /// R_ij = Σ R(λ) E_i(λ) E_j(λ) (characteristic vectors).
    Matrix(DMatrix<f64>),
}

/// Why a method could not be prepared.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpectralError {
    #[error("{0}")]
    Parameter(String),
    #[error("the characteristic vector analysis needs a family of spectra, and got none")]
    NoFamily,
}

/// A method ready to use: its wavelengths, weights or basis computed once.
#[derive(Debug, Clone)]
pub struct SpectralMethod {
    pub kind: MethodKind,
    pub band: Band,
    form: Form,
}

#[derive(Debug, Clone)]
enum Form {
    /// Samples at `wavelengths`; `weights[f][k]` is the weight of sample k in the
    /// integral of function f, or `None` where a function does not use that sample
    /// (Gaussian quadrature has its own wavelengths per function).
    Samples {
        wavelengths: Vec<f64>,
        weights: [Vec<Option<f64>>; 3],
    },
    Polynomial {
        degree: usize,
        /// Grid indices of the two spans (the split sample in both).
        spans: [Vec<usize>; 2],
        /// Least-squares projection of grid samples on each span's Chebyshev basis.
        projection: [DMatrix<f64>; 2],
        /// ∫ T_i(t) f(λ) dλ over each span for each function f, f itself the span's
        /// polynomial: `integrals[f]` has (degree + 1) per span, spans in order.
        integrals: [Vec<f64>; 3],
    },
    Basis {
        /// Grid samples × m: the characteristic vectors, orthonormal on the grid.
        vectors: DMatrix<f64>,
        /// 3 × m: T(f, i) = Σ E_i(λ) f(λ) Δλ.
        integrals: DMatrix<f64>,
    },
}

/// Where the Raso–Fournier spans split (nm).
pub const SPLIT_NM: f64 = 550.0;

/// Grid indices of each span of `band`: [380, 550] and [550, the band's end] (550 in
/// both).
fn span_indices(band: Band) -> [Vec<usize>; 2] {
    let split = ((SPLIT_NM - GRID_START_NM) / GRID_STEP_NM).round() as usize;
    let (first, last) = band.indices();
    [(first..=split).collect(), (split..=last).collect()]
}

/// Chebyshev polynomials T_0 … T_degree at t ∈ [−1, 1].
fn chebyshev(t: f64, degree: usize) -> Vec<f64> {
    let mut values = vec![1.0; degree + 1];
    if degree >= 1 {
        values[1] = t;
    }
    for k in 2..=degree {
        values[k] = 2.0 * t * values[k - 1] - values[k - 2];
    }
    values
}

/// The CMF values on the grid, one row per function.
fn cmf_on_grid(observer: Observer) -> [Vec<f64>; 3] {
    let mut out = [
        vec![0.0; GRID_LEN],
        vec![0.0; GRID_LEN],
        vec![0.0; GRID_LEN],
    ];
    for i in 0..GRID_LEN {
        if let Some(v) = observer.cmf_at(grid_nm(i)) {
            for (row, value) in out.iter_mut().zip(v) {
                row[i] = value;
            }
        }
    }
    out
}

impl SpectralMethod {
    /// Prepare `kind` for `observer`; characteristic vectors are computed from
    /// `family` (spectra on the grid, representative of the scene). Over the whole
    /// grid, 380–780 nm.
    pub fn new(
        kind: MethodKind,
        observer: Observer,
        family: &[Vec<f64>],
    ) -> Result<SpectralMethod, SpectralError> {
        SpectralMethod::in_band(kind, observer, family, Band::FULL)
    }

    /// The same over `band` only: what lies outside it is not seen.
    pub fn in_band(
        kind: MethodKind,
        observer: Observer,
        family: &[Vec<f64>],
        band: Band,
    ) -> Result<SpectralMethod, SpectralError> {
        let form = match &kind {
            MethodKind::Direct => samples_form(sampling_wavelengths(5, band), observer, 5.0),
            MethodKind::Sampling { step_nm } => {
                if *step_nm == 0 || step_nm % 5 != 0 || *step_nm > 400 {
                    return Err(SpectralError::Parameter(format!(
                        "a sampling step of {step_nm} nm (a multiple of 5 up to 400)"
                    )));
                }
                samples_form(
                    sampling_wavelengths(*step_nm, band),
                    observer,
                    *step_nm as f64,
                )
            }
            MethodKind::Gauss { points } => gauss_form(*points, observer, band)?,
            MethodKind::RasoFournier { degree } => polynomial_form(*degree, observer, band)?,
            MethodKind::CharacteristicVectors { m } => basis_form(*m, observer, family, band)?,
        };
        Ok(SpectralMethod { kind, band, form })
    }

    /// The method's representation of a spectrum given on the grid.
    pub fn represent(&self, spectrum: &[f64]) -> Represented {
        match &self.form {
            Form::Samples { wavelengths, .. } => Represented(
                wavelengths
                    .iter()
                    .map(|nm| interpolate(spectrum, *nm))
                    .collect(),
            ),
            Form::Polynomial {
                projection, spans, ..
            } => {
                let mut coefficients = Vec::new();
                for (span, indices) in spans.iter().enumerate() {
                    let values =
                        DVector::from_iterator(indices.len(), indices.iter().map(|i| spectrum[*i]));
                    coefficients.extend((&projection[span] * values).iter());
                }
                Represented(coefficients)
            }
            Form::Basis { vectors, .. } => {
                let s = DVector::from_column_slice(spectrum);
                Represented((vectors.transpose() * s).iter().copied().collect())
            }
        }
    }

    /// A reflectance (on the grid) as this method multiplies by it.
    pub fn reflectance(&self, reflectance: &[f64]) -> Reflectance {
        match &self.form {
            Form::Samples { .. } => Reflectance::Samples(self.represent(reflectance).0),
            Form::Polynomial { .. } => Reflectance::Polynomial(self.represent(reflectance).0),
            Form::Basis { vectors, .. } => {
                let m = vectors.ncols();
                Reflectance::Matrix(DMatrix::from_fn(m, m, |i, j| {
                    (0..GRID_LEN)
                        .map(|k| reflectance[k] * vectors[(k, i)] * vectors[(k, j)])
                        .sum()
                }))
            }
        }
    }

    /// Light `light` reflected once by `reflectance`.
    pub fn product(&self, reflectance: &Reflectance, light: &Represented) -> Represented {
        match (reflectance, &self.form) {
            (Reflectance::Samples(r), _) => {
                Represented(r.iter().zip(&light.0).map(|(r, s)| r * s).collect())
            }
            (Reflectance::Polynomial(r), Form::Polynomial { degree, .. }) => {
                let n = degree + 1;
                let mut out = Vec::with_capacity(2 * n);
                for span in 0..2 {
                    let (a, b) = (
                        &r[span * n..(span + 1) * n],
                        &light.0[span * n..(span + 1) * n],
                    );
                    out.extend(chebyshev_product_truncated(a, b));
                }
                Represented(out)
            }
            (Reflectance::Matrix(r), _) => {
                let s = DVector::from_column_slice(&light.0);
                Represented((r * s).iter().copied().collect())
            }
            // A reflectance made by another method: not a pairing the API gives out.
            (Reflectance::Polynomial(_), _) => light.clone(),
        }
    }

    /// XYZ of a represented spectrum, in the units of Σ S f Δλ.
    pub fn integrate(&self, spectrum: &Represented) -> Xyz {
        let s = &spectrum.0;
        match &self.form {
            Form::Samples { weights, .. } => Xyz::from_fn(|f, _| {
                weights[f]
                    .iter()
                    .zip(s)
                    .filter_map(|(w, v)| w.map(|w| w * v))
                    .sum()
            }),
            Form::Polynomial { integrals, .. } => {
                Xyz::from_fn(|f, _| integrals[f].iter().zip(s).map(|(w, v)| w * v).sum())
            }
            Form::Basis { integrals, .. } => {
                let v = integrals * DVector::from_column_slice(s);
                Xyz::new(v[0], v[1], v[2])
            }
        }
    }

    /// Operations of one spectrum–reflectance product, counted from the loops above.
    pub fn product_operations(&self) -> Operations {
        match &self.form {
            Form::Samples { wavelengths, .. } => Operations::new(wavelengths.len(), 0),
            Form::Polynomial { degree, .. } => {
                let per_span = chebyshev_product_operations(degree + 1);
                Operations::new(2 * per_span.multiplications, 2 * per_span.additions)
            }
            Form::Basis { vectors, .. } => {
                let m = vectors.ncols();
                Operations::new(m * m, m * (m - 1))
            }
        }
    }

    /// Operations of one integration to XYZ.
    pub fn integration_operations(&self) -> Operations {
        let terms = |n: usize| Operations::new(n, n.saturating_sub(1));
        let sum3 = |n: [usize; 3]| {
            let t = n.map(terms);
            Operations::new(
                t.iter().map(|o| o.multiplications).sum(),
                t.iter().map(|o| o.additions).sum(),
            )
        };
        match &self.form {
            Form::Samples { weights, .. } => {
                sum3([0, 1, 2].map(|f| weights[f].iter().filter(|w| w.is_some()).count()))
            }
            Form::Polynomial { integrals, .. } => sum3([0, 1, 2].map(|f| integrals[f].len())),
            Form::Basis { integrals, .. } => sum3([integrals.ncols(); 3]),
        }
    }
}

/// Weighted ordinates at `wavelengths` (on the grid), weight f(λ) Δλ.
fn samples_form(wavelengths: Vec<f64>, observer: Observer, step: f64) -> Form {
    let weights = [0, 1, 2].map(|f| {
        wavelengths
            .iter()
            .map(|nm| observer.cmf_at(*nm).map(|v| v[f] * step))
            .collect()
    });
    Form::Samples {
        wavelengths,
        weights,
    }
}

/// Gaussian quadrature for each colour-matching function as weight: the nodes and
/// weights of the `points`-point rule orthogonal to f(λ) dλ, by the Golub–Welsch
/// algorithm (the Jacobi matrix of the recurrence, from the discretised Stieltjes
/// procedure on the 1 nm table, then its eigen-decomposition).
fn gauss_form(points: usize, observer: Observer, band: Band) -> Result<Form, SpectralError> {
    if !(1..=20).contains(&points) {
        return Err(SpectralError::Parameter(format!(
            "{points} quadrature points per function (1 to 20)"
        )));
    }
    let nm: Vec<f64> = (band.from_nm.round() as i32..=band.to_nm.round() as i32)
        .map(f64::from)
        .collect();
    let mut wavelengths = Vec::new();
    let mut weights: [Vec<Option<f64>>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    for f in 0..3 {
        let w: Vec<f64> = nm
            .iter()
            .map(|l| observer.cmf_at(*l).map_or(0.0, |v| v[f]))
            .collect();
        let (nodes, node_weights) = gauss_rule(&nm, &w, points)?;
        for (node, weight) in nodes.iter().zip(node_weights) {
            wavelengths.push(*node);
            for (g, list) in weights.iter_mut().enumerate() {
                list.push((g == f).then_some(weight));
            }
        }
    }
    Ok(Form::Samples {
        wavelengths,
        weights,
    })
}

/// Nodes and weights of the n-point Gaussian rule for the discrete measure
/// Σ w_k δ(x − x_k) (x in nm, weights w_k Δλ with Δλ = 1 nm).
fn gauss_rule(x: &[f64], w: &[f64], n: usize) -> Result<(Vec<f64>, Vec<f64>), SpectralError> {
    // Work on t ∈ [−1, 1] so that the recurrence stays well scaled.
    let (lo, hi) = (x[0], x[x.len() - 1]);
    let t: Vec<f64> = x.iter().map(|v| (2.0 * v - lo - hi) / (hi - lo)).collect();
    let mass: f64 = w.iter().sum();
    if !(mass > 0.0) {
        return Err(SpectralError::Parameter(
            "a colour-matching function with no weight".into(),
        ));
    }
    let mut alpha = Vec::with_capacity(n);
    let mut beta = Vec::with_capacity(n);
    let mut previous = vec![0.0; t.len()];
    let mut current = vec![1.0; t.len()];
    let mut norm_previous = 1.0;
    for j in 0..n {
        let norm: f64 = w.iter().zip(&current).map(|(w, p)| w * p * p).sum();
        let a = w
            .iter()
            .zip(&current)
            .zip(&t)
            .map(|((w, p), t)| w * t * p * p)
            .sum::<f64>()
            / norm;
        let b = if j == 0 { mass } else { norm / norm_previous };
        alpha.push(a);
        beta.push(b);
        let next: Vec<f64> = (0..t.len())
            .map(|k| (t[k] - a) * current[k] - if j == 0 { 0.0 } else { b * previous[k] })
            .collect();
        previous = std::mem::replace(&mut current, next);
        norm_previous = norm;
    }
    let jacobi = DMatrix::from_fn(n, n, |i, j| {
        if i == j {
            alpha[i]
        } else if i.abs_diff(j) == 1 {
            beta[i.max(j)].sqrt()
        } else {
            0.0
        }
    });
    let eigen = SymmetricEigen::new(jacobi);
    let mut rule: Vec<(f64, f64)> = (0..n)
        .map(|k| {
            let node = eigen.eigenvalues[k];
            let v0 = eigen.eigenvectors[(0, k)];
            ((node * (hi - lo) + lo + hi) / 2.0, mass * v0 * v0)
        })
        .collect();
    rule.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(rule.into_iter().unzip())
}

/// Raso–Fournier: least-squares projection on each span's Chebyshev basis, and the
/// colour-matching functions as polynomials of the same form.
fn polynomial_form(degree: usize, observer: Observer, band: Band) -> Result<Form, SpectralError> {
    if !(1..=8).contains(&degree) {
        return Err(SpectralError::Parameter(format!(
            "polynomials of degree {degree} (1 to 8)"
        )));
    }
    let spans = span_indices(band);
    let n = degree + 1;
    let mut projection = Vec::new();
    let mut bases = Vec::new();
    for indices in &spans {
        let (a, b) = (grid_nm(indices[0]), grid_nm(indices[indices.len() - 1]));
        let basis = DMatrix::from_fn(indices.len(), n, |r, k| {
            let t = (2.0 * grid_nm(indices[r]) - a - b) / (b - a);
            chebyshev(t, degree)[k]
        });
        let pseudo_inverse = basis
            .clone()
            .pseudo_inverse(1e-12)
            .map_err(|e| SpectralError::Parameter(e.to_string()))?;
        projection.push(pseudo_inverse);
        bases.push((basis, (b - a) / 2.0));
    }
    // ∫ T_i T_j dλ over a span = (half-width) ∫_{−1}^{1} T_i T_j dt, exactly.
    let gram = DMatrix::from_fn(n, n, chebyshev_product_integral);
    let cmf = cmf_on_grid(observer);
    let integrals = [0, 1, 2].map(|f| {
        let mut out = Vec::with_capacity(2 * n);
        for (span, indices) in spans.iter().enumerate() {
            let values = DVector::from_iterator(indices.len(), indices.iter().map(|i| cmf[f][*i]));
            let c = &projection[span] * values;
            let w = &gram * c * bases[span].1;
            out.extend(w.iter());
        }
        out
    });
    let projection: [DMatrix<f64>; 2] = [projection[0].clone(), projection[1].clone()];
    Ok(Form::Polynomial {
        degree,
        spans,
        projection,
        integrals,
    })
}

/// ∫_{−1}^{1} T_i(t) T_j(t) dt = ½ [I(i + j) + I(|i − j|)], I(k) = 2/(1 − k²) for
/// even k and 0 for odd k.
fn chebyshev_product_integral(i: usize, j: usize) -> f64 {
    let integral = |k: usize| {
        if k % 2 == 1 {
            0.0
        } else {
            2.0 / (1.0 - (k * k) as f64)
        }
    };
    0.5 * (integral(i + j) + integral(i.abs_diff(j)))
}

/// The product of two Chebyshev series of n terms, truncated to n terms: with
/// T_i T_j = ½ (T_{i+j} + T_{|i−j|}), only the terms of degree below n are kept
/// (Chebyshev economisation: the degree reduction Raso and Fournier use).
fn chebyshev_product_truncated(a: &[f64], b: &[f64]) -> Vec<f64> {
    let n = a.len();
    let mut out = vec![0.0; n];
    for i in 0..n {
        for j in 0..n {
            let p = a[i] * b[j];
            if i + j < n {
                out[i + j] += p;
            }
            out[i.abs_diff(j)] += p;
        }
    }
    for v in &mut out {
        *v *= 0.5;
    }
    out
}

/// Operations of `chebyshev_product_truncated` on n terms: n² products and n halvings;
/// each product is added into one or two terms, and the first addition into each
/// (zero) term is not an operation.
fn chebyshev_product_operations(n: usize) -> Operations {
    let mut contributions = 0;
    for i in 0..n {
        for j in 0..n {
            contributions += 1 + usize::from(i + j < n);
        }
    }
    Operations::new(n * n + n, contributions - n)
}

/// Peercy: the first m eigenvectors of the family's correlation matrix Σ s sᵀ (not
/// centred, so that a spectrum is a combination of the vectors alone; the survey's
/// "covariance" with the mean kept in). Orthonormal on the grid.
fn basis_form(
    m: usize,
    observer: Observer,
    family: &[Vec<f64>],
    band: Band,
) -> Result<Form, SpectralError> {
    if family.is_empty() {
        return Err(SpectralError::NoFamily);
    }
    if !(1..=band.len()).contains(&m) {
        return Err(SpectralError::Parameter(format!(
            "m = {m} characteristic vectors (1 to {})",
            band.len()
        )));
    }
    // Only the band is seen: the family's samples outside it count as nothing, so
    // the vectors are zero there.
    let (first, last) = band.indices();
    let mut correlation = DMatrix::<f64>::zeros(GRID_LEN, GRID_LEN);
    for s in family {
        let v = DVector::from_fn(GRID_LEN, |k, _| {
            if (first..=last).contains(&k) {
                s[k]
            } else {
                0.0
            }
        });
        correlation += &v * v.transpose();
    }
    let eigen = SymmetricEigen::new(correlation);
    let mut order: Vec<usize> = (0..GRID_LEN).collect();
    order.sort_by(|a, b| eigen.eigenvalues[*b].total_cmp(&eigen.eigenvalues[*a]));
    // Zero outside the band even for vectors beyond the family's rank (whose
    // eigenvalue is nil and whose direction is then arbitrary).
    let vectors = DMatrix::from_fn(GRID_LEN, m, |k, i| {
        if (first..=last).contains(&k) {
            eigen.eigenvectors[(k, order[i])]
        } else {
            0.0
        }
    });
    let cmf = cmf_on_grid(observer);
    let integrals = DMatrix::from_fn(3, m, |f, i| {
        (first..=last)
            .map(|k| vectors[(k, i)] * cmf[f][k] * GRID_STEP_NM)
            .sum()
    });
    Ok(Form::Basis { vectors, integrals })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn smooth(k: usize) -> Vec<f64> {
        (0..GRID_LEN)
            .map(|i| 0.5 + 0.4 * ((i as f64) * 0.07 * (k as f64 + 1.0)).sin())
            .collect()
    }

    #[test]
    fn gauss_rule_integrates_polynomials_exactly() {
        let x: Vec<f64> = (380..=780).map(f64::from).collect();
        let w: Vec<f64> = x
            .iter()
            .map(|l| (-(l - 560.0f64).powi(2) / 5000.0).exp())
            .collect();
        let (nodes, weights) = gauss_rule(&x, &w, 4).unwrap();
        // Exact for degree ≤ 2n − 1 = 7 against the discrete measure.
        for p in 0..=7 {
            let f = |l: f64| ((l - 580.0) / 200.0).powi(p);
            let exact: f64 = x.iter().zip(&w).map(|(l, w)| w * f(*l)).sum();
            let rule: f64 = nodes.iter().zip(&weights).map(|(l, w)| w * f(*l)).sum();
            assert!((rule - exact).abs() < 1e-9 * exact.abs().max(1e-3), "x^{p}");
        }
    }

    #[test]
    fn chebyshev_product_matches_the_polynomial_product_below_the_cut() {
        let (a, b) = ([0.3, -0.2, 0.5, 0.1], [1.0, 0.4, -0.3, 0.2]);
        let out = chebyshev_product_truncated(&a, &b);
        // At any t, the full product minus its degree-4…6 Chebyshev terms.
        let full = |t: f64| {
            let (ta, tb) = (chebyshev(t, 3), chebyshev(t, 3));
            let va: f64 = a.iter().zip(&ta).map(|(c, v)| c * v).sum();
            let vb: f64 = b.iter().zip(&tb).map(|(c, v)| c * v).sum();
            va * vb
        };
        let mut high = [0.0; 7];
        for i in 0..4 {
            for j in 0..4 {
                high[i + j] += 0.5 * a[i] * b[j];
                high[i.abs_diff(j)] += 0.5 * a[i] * b[j];
            }
        }
        for t in [-0.9, -0.3, 0.2, 0.8] {
            let tc = chebyshev(t, 6);
            let kept: f64 = out.iter().zip(&tc).map(|(c, v)| c * v).sum();
            let dropped: f64 = (4..7).map(|k| high[k] * tc[k]).sum();
            assert!((kept + dropped - full(t)).abs() < 1e-12);
        }
        // Operation count: 16 products + 4 halvings; 16 + 10 contributions − 4.
        assert_eq!(chebyshev_product_operations(4), Operations::new(20, 22));
    }

    #[test]
    fn direct_integration_is_the_weighted_ordinate_sum() {
        let method = SpectralMethod::new(MethodKind::Direct, Observer::default(), &[]).unwrap();
        let s = smooth(1);
        let xyz = method.integrate(&method.represent(&s));
        let cmf = cmf_on_grid(Observer::default());
        let y: f64 = (0..GRID_LEN).map(|i| s[i] * cmf[1][i] * 5.0).sum();
        assert!((xyz.y - y).abs() < 1e-12 * y);
        assert_eq!(method.integration_operations(), Operations::new(243, 240));
        assert_eq!(method.product_operations(), Operations::new(81, 0));
    }

    #[test]
    fn a_full_basis_reproduces_every_spectrum_and_product() {
        let family: Vec<Vec<f64>> = (0..5).map(smooth).collect();
        let direct = SpectralMethod::new(MethodKind::Direct, Observer::default(), &[]).unwrap();
        let cva = SpectralMethod::new(
            MethodKind::CharacteristicVectors { m: GRID_LEN },
            Observer::default(),
            &family,
        )
        .unwrap();
        let (light, r) = (smooth(2), smooth(4));
        let reference =
            direct.integrate(&direct.product(&direct.reflectance(&r), &direct.represent(&light)));
        let got = cva.integrate(&cva.product(&cva.reflectance(&r), &cva.represent(&light)));
        assert!((got - reference).norm() < 1e-9 * reference.norm());
        assert_eq!(
            cva.product_operations(),
            Operations::new(GRID_LEN * GRID_LEN, GRID_LEN * (GRID_LEN - 1))
        );
    }
}
