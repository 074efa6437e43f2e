//! A data file's bonds and angles as distance constraints: [`Rigid`], the
//! `fix shake … b … a …` of LAMMPS (docs.lammps.org/fix_shake.html) on the
//! particle path.

use super::{FileError, LammpsData};
use crate::particles::stencils::Distance;
use crate::particles::{ParticleState, ParticleSystem, Table};
use std::collections::{BTreeMap, HashMap};

/// Which bonds and angles of a [`LammpsData`] become distance constraints,
/// and at which lengths; [`build`](Self::build) makes the system and its
/// state. Made by [`LammpsData::rigid`].
///
/// - A constrained bond of type t holds its atoms at the length given by
///   [`bond_length`](Self::bond_length), else at r0 of a harmonic `Bond
///   Coeffs` line (`t K r0`).
/// - A constrained angle i–j–k of type t holds i and k at the distance
///   √(b₁² + b₂² − 2 b₁ b₂ cos θ), b₁ and b₂ the lengths of the bonds i–j
///   and j–k and θ the angle given by [`angle_degrees`](Self::angle_degrees),
///   else θ0 of a harmonic `Angle Coeffs` line; 2 b sin(θ/2) when b₁ = b₂ =
///   b. This is how LAMMPS' `fix shake … a` constrains an angle.
///
/// By default every bond type and every angle type is constrained. The
/// constraints form one family, `bond`, of [`Distance`] rows sorted by
/// (smaller, larger) particle index, so that a molecule's rows are
/// neighbours in memory; the state is the file's unwrapped positions and
/// p = m v.
///
/// ```
/// use geoshake_runtime::particles::io::parse_lammps_data;
/// let text = "water\n\n3 atoms\n2 bonds\n1 angles\n2 atom types\n\n\
///     Masses\n\n1 15.9994\n2 1.008\n\n\
///     Atoms # molecular\n\n1 1 1 0 0 0\n2 1 2 1 0 0\n3 1 2 0 1 0\n\n\
///     Bonds\n\n1 1 1 2\n2 1 1 3\n\nAngles\n\n1 1 2 1 3\n\n\
///     Bond Coeffs # harmonic\n\n1 450 1.0\n";
/// let data = parse_lammps_data(text, "water.data").unwrap();
/// let (system, state) = data.rigid().angle_degrees(1, 90.0).build().unwrap();
/// assert_eq!((system.particles(), system.constraints()), (3, 3));
/// let hh = system.constraint_families()[0].table().data(2)[0];
/// assert!((hh - 2f64.sqrt()).abs() < 1e-15);
/// assert_eq!(state.q()[3], 1.0);
/// ```
#[derive(Clone, Debug)]
pub struct Rigid<'a> {
    data: &'a LammpsData,
    bond_types: Option<Vec<u32>>,
    angle_types: Option<Vec<u32>>,
    bond_lengths: BTreeMap<u32, f64>,
    angles: BTreeMap<u32, f64>,
}

impl LammpsData {
    /// The builder of this file's rigid bonds and angles: see [`Rigid`].
    pub fn rigid(&self) -> Rigid<'_> {
        Rigid {
            data: self,
            bond_types: None,
            angle_types: None,
            bond_lengths: BTreeMap::new(),
            angles: BTreeMap::new(),
        }
    }
}

/// r0 (harmonic bonds) or θ0 (harmonic angles) of a coefficient line: the
/// second number of `K r0`, when the section's style is harmonic or not
/// named.
fn harmonic(coeffs: &BTreeMap<u32, Vec<f64>>, style: &Option<String>, t: u32) -> Option<f64> {
    let harmonic = style
        .as_deref()
        .is_none_or(|s| s.split_whitespace().next() == Some("harmonic"));
    match coeffs.get(&t).map(Vec::as_slice) {
        Some(&[_, x]) if harmonic => Some(x),
        _ => None,
    }
}

impl<'a> Rigid<'a> {
    /// Constrain the bonds of these types only (default: all).
    pub fn bonds(mut self, types: &[u32]) -> Self {
        self.bond_types = Some(types.to_vec());
        self
    }

    /// Constrain the angles of these types only (default: all; `&[]`
    /// for none).
    pub fn angles(mut self, types: &[u32]) -> Self {
        self.angle_types = Some(types.to_vec());
        self
    }

    /// The length of bonds of type `t` (overrides `Bond Coeffs`).
    pub fn bond_length(mut self, t: u32, length: f64) -> Self {
        self.bond_lengths.insert(t, length);
        self
    }

    /// The angle of type `t`, in degrees (overrides `Angle Coeffs`).
    pub fn angle_degrees(mut self, t: u32, theta: f64) -> Self {
        self.angles.insert(t, theta);
        self
    }

    fn bond_len(&self, t: u32) -> Result<f64, FileError> {
        let d = self.data;
        self.bond_lengths
            .get(&t)
            .copied()
            .or_else(|| harmonic(&d.bond_coeffs, &d.bond_style, t))
            .ok_or(FileError::MissingLength {
                file: d.file.clone(),
                kind: "bond",
                type_id: t,
                what: "length",
            })
    }

    /// The constraint table: one row (a, b; length) per constrained bond
    /// and angle, sorted by (min(a, b), max(a, b)).
    pub fn table(&self) -> Result<Table, FileError> {
        let d = self.data;
        let chosen =
            |types: &Option<Vec<u32>>, t: u32| types.as_ref().is_none_or(|v| v.contains(&t));
        let mut rows: Vec<(usize, usize, f64)> = Vec::new();
        for b in d
            .bonds
            .iter()
            .filter(|b| chosen(&self.bond_types, b.bond_type))
        {
            rows.push((b.atoms[0], b.atoms[1], self.bond_len(b.bond_type)?));
        }
        let angles: Vec<_> = d
            .angles
            .iter()
            .filter(|a| chosen(&self.angle_types, a.angle_type))
            .collect();
        if !angles.is_empty() {
            let bond_type: HashMap<(usize, usize), u32> = d
                .bonds
                .iter()
                .map(|b| {
                    (
                        (b.atoms[0].min(b.atoms[1]), b.atoms[0].max(b.atoms[1])),
                        b.bond_type,
                    )
                })
                .collect();
            for a in angles {
                let [i, j, k] = a.atoms;
                let leg = |x: usize, y: usize| -> Result<f64, FileError> {
                    let t = bond_type.get(&(x.min(y), x.max(y))).ok_or(
                        FileError::AngleWithoutBond {
                            file: d.file.clone(),
                            line: a.line,
                            a: d.ids[x],
                            b: d.ids[y],
                        },
                    )?;
                    self.bond_len(*t)
                };
                let (b1, b2) = (leg(i, j)?, leg(j, k)?);
                let theta = self
                    .angles
                    .get(&a.angle_type)
                    .copied()
                    .or_else(|| harmonic(&d.angle_coeffs, &d.angle_style, a.angle_type))
                    .ok_or(FileError::MissingLength {
                        file: d.file.clone(),
                        kind: "angle",
                        type_id: a.angle_type,
                        what: "angle",
                    })?
                    .to_radians();
                let r = if b1 == b2 {
                    2.0 * b1 * (theta / 2.0).sin()
                } else {
                    (b1 * b1 + b2 * b2 - 2.0 * b1 * b2 * theta.cos()).sqrt()
                };
                rows.push((i, k, r));
            }
        }
        rows.sort_by_key(|&(a, b, _)| (a.min(b), a.max(b)));
        let mut table = Table::with_capacity(2, 1, rows.len());
        for (a, b, l) in rows {
            table
                .push(&[a, b], &[l])
                .map_err(|source| FileError::Topology {
                    file: d.file.clone(),
                    source,
                })?;
        }
        Ok(table)
    }

    /// The system (the file's masses, the constraint family `bond` when
    /// there is a constraint) and its state (unwrapped positions, p = m v,
    /// step 0, time 0).
    pub fn build(&self) -> Result<(ParticleSystem, ParticleState), FileError> {
        let d = self.data;
        let topology = |source| FileError::Topology {
            file: d.file.clone(),
            source,
        };
        let table = self.table()?;
        let mut system = ParticleSystem::new(3, d.masses.clone()).map_err(topology)?;
        if !table.is_empty() {
            system = system
                .with_constraints("bond", Distance::<3>, table)
                .map_err(topology)?;
        }
        Ok((system, ParticleState::new(d.positions.clone(), d.momenta())))
    }
}
