//! Drive readings of the twin sampled at servo rate, for the live stack: what the drive
//! interface would report while the machine holds or follows a path. The noise is the twin's
//! own (its encoders, its thermometer), drawn from a generator seeded apart from the
//! campaign's draws so that adding a stream does not change the campaign measured before it.

use super::machine::{gauss, Twin, TwinError, TEMP_SENSOR_K};
use rand::rngs::StdRng;
use rand::SeedableRng;

/// One sample of the drives: what the machine reports, mm, N, °C.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveSample {
    /// Drive positions: the command on holding drives, the encoder on followers.
    pub q: [f64; 4],
    pub force: [f64; 4],
    pub follower: [bool; 4],
    /// The machine thermometer (`temp_machine`).
    pub temp_c: f64,
}

/// A stream of drive samples of one twin.
pub struct DriveStream<'a> {
    twin: &'a Twin,
    rng: StdRng,
    /// 1 with the twin's noise, 0 noiseless (the draws are still made, so that a noiseless
    /// and a noisy stream of one seed differ by the noise only).
    k: f64,
    encoder_mm: f64,
}

impl<'a> DriveStream<'a> {
    pub fn new(twin: &'a Twin) -> DriveStream<'a> {
        let noise = twin.config().noise.as_ref();
        DriveStream {
            twin,
            rng: StdRng::seed_from_u64(twin.config().seed ^ 0x5eed_57ea_0000_0001),
            k: if noise.is_some() { 1.0 } else { 0.0 },
            encoder_mm: noise.map_or(0.0, |n| n.encoder_mm),
        }
    }

    /// The drives holding the TCP at (x, y) at time `t`, s, with `offset` (mm) added to the
    /// holding drives' encoder errors (a drifting drive).
    pub fn sample(
        &mut self,
        x: f64,
        y: f64,
        t: f64,
        offset: [f64; 4],
    ) -> Result<DriveSample, TwinError> {
        let mut enc = [0.0; 4];
        for (e, o) in enc.iter_mut().zip(offset) {
            *e = self.k * self.encoder_mm * gauss(&mut self.rng) + o;
        }
        let st = self.twin.machine_state("stream", x, y, t, enc, false)?;
        let mut q = st.q;
        for (qi, &follower) in q.iter_mut().zip(&st.follower) {
            if follower {
                *qi += self.k * self.encoder_mm * gauss(&mut self.rng);
            }
        }
        let temp_c = self.twin.thermometer(t) + self.k * TEMP_SENSOR_K * gauss(&mut self.rng);
        Ok(DriveSample {
            q,
            force: st.f,
            follower: st.follower,
            temp_c,
        })
    }
}
