//! The simulation box of LAMMPS: [`SimBox`].

/// A periodic box as LAMMPS stores it (read_data, "Triclinic simulation
/// box"): lower and upper bounds per axis and the tilt factors xy, xz, yz.
/// Its edge vectors are a = (lx, 0, 0), b = (xy, ly, 0), c = (xz, yz, lz),
/// lx = xhi − xlo and so on; all tilts 0 is an orthogonal box.
///
/// ```
/// use geoshake_runtime::particles::io::SimBox;
/// let b = SimBox::orthogonal([0.0; 3], [2.0, 3.0, 4.0]).with_tilt([0.5, 0.0, 0.0]);
/// assert!(b.is_triclinic());
/// assert_eq!(b.edges(), [[2.0, 0.0, 0.0], [0.5, 3.0, 0.0], [0.0, 0.0, 4.0]]);
/// // An atom with image flags (1, 1, 0) sits one a and one b further.
/// assert_eq!(b.unwrap([0.1, 0.2, 0.3], [1, 1, 0]), [2.6, 3.2, 0.3]);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SimBox {
    /// xlo, ylo, zlo.
    pub lo: [f64; 3],
    /// xhi, yhi, zhi.
    pub hi: [f64; 3],
    /// xy, xz, yz.
    pub tilt: [f64; 3],
}

impl Default for SimBox {
    /// LAMMPS' default when a data file gives no bounds: [−0.5, 0.5]³.
    fn default() -> Self {
        SimBox::orthogonal([-0.5; 3], [0.5; 3])
    }
}

impl SimBox {
    /// An orthogonal box [lo, hi].
    pub fn orthogonal(lo: [f64; 3], hi: [f64; 3]) -> Self {
        SimBox {
            lo,
            hi,
            tilt: [0.0; 3],
        }
    }

    /// The same box with tilt factors xy, xz, yz.
    pub fn with_tilt(mut self, tilt: [f64; 3]) -> Self {
        self.tilt = tilt;
        self
    }

    /// Whether a tilt factor is not zero.
    pub fn is_triclinic(&self) -> bool {
        self.tilt != [0.0; 3]
    }

    /// lx, ly, lz.
    pub fn lengths(&self) -> [f64; 3] {
        [0, 1, 2].map(|c| self.hi[c] - self.lo[c])
    }

    /// The edge vectors a, b, c (rows).
    pub fn edges(&self) -> [[f64; 3]; 3] {
        let [lx, ly, lz] = self.lengths();
        let [xy, xz, yz] = self.tilt;
        [[lx, 0.0, 0.0], [xy, ly, 0.0], [xz, yz, lz]]
    }

    /// x + i·a + j·b + k·c for image flags (i, j, k): the unwrapped
    /// position of an atom that crossed the periodic boundaries.
    pub fn unwrap(&self, x: [f64; 3], image: [i32; 3]) -> [f64; 3] {
        let e = self.edges();
        let mut out = x;
        for (k, &n) in image.iter().enumerate() {
            if n != 0 {
                for c in 0..3 {
                    out[c] += f64::from(n) * e[k][c];
                }
            }
        }
        out
    }

    /// The bounds of LAMMPS' dump header for a triclinic box: xlo_bound =
    /// xlo + min(0, xy, xz, xy + xz), xhi_bound = xhi + max(…), ylo_bound
    /// = ylo + min(0, yz), yhi_bound = yhi + max(0, yz) (the dump page,
    /// "triclinic simulation boxes").
    pub(crate) fn dump_bounds(&self) -> [[f64; 2]; 3] {
        let [xy, xz, yz] = self.tilt;
        let xs = [0.0, xy, xz, xy + xz];
        let lo_x = xs.iter().copied().fold(f64::INFINITY, f64::min);
        let hi_x = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        [
            [self.lo[0] + lo_x, self.hi[0] + hi_x],
            [self.lo[1] + yz.min(0.0), self.hi[1] + yz.max(0.0)],
            [self.lo[2], self.hi[2]],
        ]
    }

    /// The box whose dump header bounds are `bounds` with tilt `tilt`: the
    /// inverse of `dump_bounds`, exact up to the rounding of one addition.
    pub(crate) fn from_dump_bounds(bounds: [[f64; 2]; 3], tilt: [f64; 3]) -> Self {
        let [xy, xz, yz] = tilt;
        let xs = [0.0, xy, xz, xy + xz];
        let lo_x = xs.iter().copied().fold(f64::INFINITY, f64::min);
        let hi_x = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        SimBox {
            lo: [
                bounds[0][0] - lo_x,
                bounds[1][0] - yz.min(0.0),
                bounds[2][0],
            ],
            hi: [
                bounds[0][1] - hi_x,
                bounds[1][1] - yz.max(0.0),
                bounds[2][1],
            ],
            tilt,
        }
    }
}
