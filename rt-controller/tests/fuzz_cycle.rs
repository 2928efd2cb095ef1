//! Property test of the control cycle over arbitrary messages (NaN, ±inf,
//! huge values, denormals, torn headers in every field), on the Panda and
//! the iiwa 14: no panic, torques finite and within the torque and rate
//! limits, the right fault in the sensor frame. The long run is
//! `cargo run --release -p rt-controller --example fuzz_cycle -- 1000000`.

#[path = "common/fuzz.rs"]
mod fuzz;

use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 3000,
        ..ProptestConfig::default()
    })]

    #[test]
    fn the_cycle_survives_arbitrary_messages(case in fuzz::case()) {
        fuzz::check(&case)?;
    }
}
