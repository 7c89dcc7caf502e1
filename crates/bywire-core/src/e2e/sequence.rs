//! The receive-side state machine shared by AUTOSAR E2E Profiles 1 and 2.

/// Outcome of checking one reception (`E2E_P01CheckStatusType` / `E2E_P02CheckStatusType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CheckStatus {
    /// New data, correct CRC, counter one ahead.
    Ok,
    /// The check was called with no new data.
    NoNewData,
    /// The CRC does not match: the data are corrupted or not for this data ID.
    WrongCrc,
    /// Correct, but the receiver is still resynchronising after a sequence error; do not use
    /// the data yet.
    Sync,
    /// The first correct data after start: nothing to compare the counter with yet.
    Initial,
    /// Correct CRC, same counter as before: repeated data.
    Repeated,
    /// Correct, with some values lost in between, within the allowed gap.
    OkSomeLost,
    /// The counter jumped further than allowed.
    WrongSequence,
}

/// Receiver configuration common to both profiles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SequenceConfig {
    /// Largest counter step accepted right after a correct reception (`MaxDeltaCounterInit`).
    pub max_delta_counter_init: u8,
    /// Most calls without new or with repeated data before a resynchronisation
    /// (`MaxNoNewOrRepeatedData`).
    pub max_no_new_or_repeated_data: u8,
    /// Correct receptions needed to leave resynchronisation (`SyncCounterInit`).
    pub sync_counter_init: u8,
}

impl Default for SequenceConfig {
    fn default() -> Self {
        SequenceConfig {
            max_delta_counter_init: 1,
            max_no_new_or_repeated_data: 0,
            sync_counter_init: 0,
        }
    }
}

/// The check state (`E2E_P0xCheckStateType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) struct SequenceState {
    pub modulus: u8,
    pub last_valid_counter: u8,
    pub max_delta_counter: u8,
    pub wait_for_first_data: bool,
    pub lost_data: u8,
    pub no_new_or_repeated_data_counter: u8,
    pub sync_counter: u8,
}

impl SequenceState {
    pub fn new(modulus: u8) -> Self {
        SequenceState {
            modulus: modulus.max(2),
            last_valid_counter: 0,
            max_delta_counter: 0,
            wait_for_first_data: true,
            lost_data: 0,
            no_new_or_repeated_data_counter: 0,
            sync_counter: 0,
        }
    }

    /// One check of `data` (`None`: no new data), with `read` giving the counter of data whose
    /// CRC (and data ID) is right and `Err(())` otherwise: the part both profiles share.
    pub fn check_data<E>(
        &mut self,
        config: &SequenceConfig,
        data: Option<&[u8]>,
        read: impl FnOnce(&[u8]) -> Result<Result<u8, ()>, E>,
    ) -> Result<CheckStatus, E> {
        let received = data.map(read).transpose()?;
        Ok(self.check(config, received))
    }

    /// One check, after the profile has read the counter and verified the CRC.
    /// `received` is `None` when there was no new data, `Some(Err(()))` on a CRC mismatch.
    pub fn check(
        &mut self,
        config: &SequenceConfig,
        received: Option<Result<u8, ()>>,
    ) -> CheckStatus {
        let top = self.modulus - 1;
        if self.max_delta_counter < top {
            self.max_delta_counter += 1;
        }
        let counter = match received {
            None => {
                if self.no_new_or_repeated_data_counter < top {
                    self.no_new_or_repeated_data_counter += 1;
                }
                return CheckStatus::NoNewData;
            }
            Some(Err(())) => return CheckStatus::WrongCrc,
            Some(Ok(counter)) => counter % self.modulus,
        };
        if self.wait_for_first_data {
            self.wait_for_first_data = false;
            self.max_delta_counter = config.max_delta_counter_init;
            self.last_valid_counter = counter;
            return CheckStatus::Initial;
        }
        let delta = (counter + self.modulus - self.last_valid_counter) % self.modulus;
        if delta == 0 {
            if self.no_new_or_repeated_data_counter < top {
                self.no_new_or_repeated_data_counter += 1;
            }
            return CheckStatus::Repeated;
        }
        if delta > self.max_delta_counter {
            self.no_new_or_repeated_data_counter = 0;
            self.sync_counter = config.sync_counter_init;
            if self.sync_counter > 0 {
                self.max_delta_counter = config.max_delta_counter_init;
                self.last_valid_counter = counter;
            }
            return CheckStatus::WrongSequence;
        }
        self.max_delta_counter = config.max_delta_counter_init;
        self.last_valid_counter = counter;
        self.lost_data = delta - 1;
        if self.no_new_or_repeated_data_counter <= config.max_no_new_or_repeated_data {
            self.no_new_or_repeated_data_counter = 0;
            if self.sync_counter > 0 {
                self.sync_counter -= 1;
                return CheckStatus::Sync;
            }
            if delta == 1 {
                CheckStatus::Ok
            } else {
                CheckStatus::OkSomeLost
            }
        } else {
            self.sync_counter = config.sync_counter_init;
            self.no_new_or_repeated_data_counter = 0;
            CheckStatus::Sync
        }
    }
}

/// What a profile tells the shared receiver: its counter range, its settings and how to read
/// one reception.
pub trait Profile {
    /// The profile's settings.
    type Config;
    /// Counter values run `0..MODULUS`.
    const MODULUS: u8;
    /// The receiver sequence settings within `config`.
    fn sequence(config: &Self::Config) -> &SequenceConfig;
    /// The counter of `data` when its CRC (and data ID) check out, `Err(())` when not.
    fn read(config: &Self::Config, data: &[u8]) -> Result<Result<u8, ()>, super::error::E2eError>;
}

/// The receiver of a profile: waits for its first data, then judges each reception.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Checker<P> {
    state: SequenceState,
    profile: core::marker::PhantomData<P>,
}

impl<P: Profile> Default for Checker<P> {
    fn default() -> Self {
        Checker {
            state: SequenceState::new(P::MODULUS),
            profile: core::marker::PhantomData,
        }
    }
}

impl<P: Profile> Checker<P> {
    /// A receiver waiting for its first data.
    pub fn new() -> Self {
        Self::default()
    }

    /// Check `data` (`None`: the check ran with no new data).
    pub fn check(
        &mut self,
        config: &P::Config,
        data: Option<&[u8]>,
    ) -> Result<CheckStatus, super::error::E2eError> {
        self.state
            .check_data(P::sequence(config), data, |d| P::read(config, d))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// AUTOSAR's defaults: one step ahead per call, no missed call tolerated, no resynchronisation.
    #[test]
    fn the_default_allows_one_step_and_no_repeats() {
        let config = SequenceConfig::default();
        assert_eq!(
            (
                config.max_delta_counter_init,
                config.max_no_new_or_repeated_data,
                config.sync_counter_init
            ),
            (1, 0, 0)
        );
        let mut state = SequenceState::new(16);
        // Each check call widens the step allowed by one (a call may have found nothing new).
        let statuses =
            [Some(Ok(0)), Some(Ok(1)), Some(Ok(3)), Some(Ok(6))].map(|r| state.check(&config, r));
        assert_eq!(
            statuses,
            [
                CheckStatus::Initial,
                CheckStatus::Ok,
                CheckStatus::OkSomeLost,
                CheckStatus::WrongSequence
            ]
        );
        assert_eq!(state.lost_data, 1, "one value lost between 1 and 3");
    }

    /// After more calls without new data than allowed, the data are held back until
    /// `sync_counter_init` more correct receptions have come.
    #[test]
    fn too_many_calls_without_new_data_resynchronise_before_data_is_used_again() {
        let config = SequenceConfig {
            max_delta_counter_init: 1,
            max_no_new_or_repeated_data: 0,
            sync_counter_init: 2,
        };
        let mut state = SequenceState::new(16);
        let receptions = [
            Some(Ok(0)),
            None,
            Some(Ok(1)),
            Some(Ok(2)),
            Some(Ok(3)),
            Some(Ok(4)),
        ];
        let statuses = receptions.map(|r| state.check(&config, r));
        assert_eq!(
            statuses,
            [
                CheckStatus::Initial,
                CheckStatus::NoNewData,
                CheckStatus::Sync,
                CheckStatus::Sync,
                CheckStatus::Sync,
                CheckStatus::Ok
            ]
        );
    }

    /// The count of calls without new data saturates below the modulus: a tolerance of that
    /// many lets any run of them through.
    #[test]
    fn calls_without_new_data_are_counted_up_to_the_modulus_less_one() {
        let config = SequenceConfig {
            max_delta_counter_init: 15,
            max_no_new_or_repeated_data: 15,
            sync_counter_init: 3,
        };
        let mut state = SequenceState::new(16);
        assert_eq!(state.check(&config, Some(Ok(0))), CheckStatus::Initial);
        for _ in 0..40 {
            assert_eq!(state.check(&config, Some(Ok(0))), CheckStatus::Repeated);
        }
        assert_eq!(state.no_new_or_repeated_data_counter, 15);
        assert_eq!(state.check(&config, Some(Ok(1))), CheckStatus::Ok);
        for _ in 0..40 {
            assert_eq!(state.check(&config, None), CheckStatus::NoNewData);
        }
        assert_eq!(state.check(&config, Some(Ok(2))), CheckStatus::Ok);
    }

    /// A counter read beyond the modulus is taken modulo it, without overflow.
    #[test]
    fn a_counter_beyond_the_modulus_is_taken_modulo_it() {
        let config = SequenceConfig::default();
        let mut state = SequenceState::new(16);
        assert_eq!(state.check(&config, Some(Ok(250))), CheckStatus::Initial);
        assert_eq!(state.last_valid_counter, 10);
        assert_eq!(state.check(&config, Some(Ok(11))), CheckStatus::Ok);
    }
}
