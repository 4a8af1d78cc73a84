//! How the carriers moved to a pose: the direction of each carrier's last move and the way
//! it travelled since its last reversal, along a sequence of poses. One definition for a
//! campaign's derived covariates (`dir_q1`.., `travel_q1`.., `t_run`:
//! [`super::Campaign::derived_covariates`]) and for a live stream of drive states (the nodes
//! that apply a calibrated effect reading them): an effect fitted on the one is applied to
//! the other with the same numbers.

/// A move smaller than this (mm) is no move: the carrier keeps the direction it last moved in.
pub const STANDSTILL_MM: f64 = 1e-9;

/// The direction of each carrier's last move after a move `from` → `to` (mm), starting from
/// `dir`: a carrier that does not move keeps its direction.
pub fn next_direction(dir: [f64; 4], from: &[f64; 4], to: &[f64; 4]) -> [f64; 4] {
    let mut out = dir;
    for a in 0..4 {
        let dq = to[a] - from[a];
        if dq.abs() > STANDSTILL_MM {
            out[a] = dq.signum();
        }
    }
    out
}

/// The derived covariates of one pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionCovariates {
    /// ±1: the direction of each carrier's last move (+1 before any move).
    pub dir: [f64; 4],
    /// mm moved since each carrier's last reversal.
    pub travel: [f64; 4],
    /// s since the first pose of the sequence.
    pub t_run: f64,
}

/// The state of a sequence of poses: the last pose's carriers, time and covariates.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Motion {
    last: Option<([f64; 4], MotionCovariates)>,
    t0: f64,
}

impl Motion {
    /// The covariates of the next pose of the sequence, at carriers `q` (mm) and time `t` (s).
    pub fn next(&mut self, q: [f64; 4], t: f64) -> MotionCovariates {
        let now = match self.last {
            None => {
                self.t0 = t;
                MotionCovariates {
                    dir: [1.0; 4],
                    travel: [0.0; 4],
                    t_run: 0.0,
                }
            }
            Some((prev_q, prev)) => {
                let dir = next_direction(prev.dir, &prev_q, &q);
                let mut travel = [0.0; 4];
                for a in 0..4 {
                    let moved = (q[a] - prev_q[a]).abs();
                    travel[a] = if dir[a].total_cmp(&prev.dir[a]).is_eq() {
                        prev.travel[a] + moved
                    } else {
                        moved
                    };
                }
                MotionCovariates {
                    dir,
                    travel,
                    t_run: t - self.t0,
                }
            }
        };
        self.last = Some((q, now));
        now
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direction, travel and run time of carrier 4 as expected.
    fn is(m: MotionCovariates, (dir, travel, t_run): (f64, f64, f64)) -> bool {
        [m.dir[3] - dir, m.travel[3] - travel, m.t_run - t_run]
            .iter()
            .all(|d| d.abs() < 1e-12)
    }

    #[test]
    fn a_reversal_restarts_the_travel_and_a_standstill_keeps_the_direction() {
        let mut m = Motion::default();
        let at = |q4: f64| [0.0, 0.0, 0.0, q4];
        assert!(is(m.next(at(10.0), 5.0), (1.0, 0.0, 0.0)));
        assert!(is(m.next(at(7.5), 6.0), (-1.0, 2.5, 1.0)));
        assert!(is(m.next(at(7.5), 7.0), (-1.0, 2.5, 2.0)), "standstill");
        assert!(is(m.next(at(7.0), 8.0), (-1.0, 3.0, 3.0)));
        let up = m.next(at(8.0), 9.0);
        assert!(is(up, (1.0, 1.0, 4.0)), "{up:?}");
        assert!(
            (up.dir[0] - 1.0).abs() < 1e-12,
            "a carrier that never moved: +1"
        );
    }
}
