//! Wrapping angles and measuring the distance between them, each function with its range.
//!
//! Several conventions coexist because callers need them: the boundaries differ by which
//! end of the interval is closed. A NaN or infinite input gives NaN.

use std::f64::consts::{PI, TAU};

/// `a` (radians) moved by a multiple of 2 pi into (-pi, pi].
pub fn wrap_angle(a: f64) -> f64 {
    let mut r = a % TAU;
    if r <= -PI {
        r += TAU;
    } else if r > PI {
        r -= TAU;
    }
    r
}

/// `a` moved by a multiple of `period` into (-period / 2, period / 2]: the nearest
/// representative of `a` modulo `period`, +period / 2 at the tie.
pub fn wrap_to_half_period(a: f64, period: f64) -> f64 {
    let r = a.rem_euclid(period);
    if r > 0.5 * period { r - period } else { r }
}

/// `a` moved by a multiple of `period` into [-period / 2, period / 2): the nearest
/// representative of `a` modulo `period`, -period / 2 at the tie.
pub fn wrap_to_half_period_floor(a: f64, period: f64) -> f64 {
    (a + 0.5 * period).rem_euclid(period) - 0.5 * period
}

/// `a` moved by a multiple of `period` into [0, period) (`f64::rem_euclid`: a negative `a`
/// smaller in magnitude than half an ulp of `period` rounds to `period` itself).
pub fn wrap_positive(a: f64, period: f64) -> f64 {
    a.rem_euclid(period)
}

/// Distance between the angles `a` and `b` modulo `period`, in [0, period / 2].
pub fn distance(a: f64, b: f64, period: f64) -> f64 {
    let d = (a - b).rem_euclid(period);
    d.min(period - d)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TOL: f64 = 1e-12;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < TOL
    }

    #[test]
    fn wrap_angle_keeps_pi_and_maps_minus_pi_to_pi() {
        assert_eq!(wrap_angle(PI), PI);
        assert_eq!(wrap_angle(-PI), PI);
        assert_eq!(wrap_angle(0.0), 0.0);
        assert!(close(wrap_angle(3.0 * PI), PI));
    }

    #[test]
    fn wrap_angle_removes_multiples_of_two_pi_from_both_signs() {
        for k in -5..=5 {
            let a = 0.3 + f64::from(k) * TAU;
            assert!(close(wrap_angle(a), 0.3), "k = {k}");
            assert!(close(wrap_angle(-a), -0.3), "k = {k}");
        }
        assert!(close(wrap_angle(1.5 * PI), -0.5 * PI));
        assert!(close(wrap_angle(-1.5 * PI), 0.5 * PI));
    }

    #[test]
    fn every_wrap_gives_nan_for_nan_and_infinity() {
        for a in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(wrap_angle(a).is_nan());
            assert!(wrap_to_half_period(a, TAU).is_nan());
            assert!(wrap_to_half_period_floor(a, TAU).is_nan());
            assert!(wrap_positive(a, TAU).is_nan());
            assert!(distance(a, 0.0, TAU).is_nan());
        }
    }

    #[test]
    fn half_period_wraps_differ_only_at_the_tie() {
        let p = TAU / 3.0;
        assert_eq!(wrap_to_half_period(0.5 * p, p), 0.5 * p);
        assert_eq!(wrap_to_half_period(-0.5 * p, p), 0.5 * p);
        assert_eq!(wrap_to_half_period_floor(0.5 * p, p), -0.5 * p);
        assert!(close(wrap_to_half_period_floor(-0.5 * p, p), -0.5 * p));
        for a in [0.1, -0.1, 0.4 * p, -0.4 * p] {
            for k in -3..=3 {
                let shifted = a + f64::from(k) * p;
                assert!(close(wrap_to_half_period(shifted, p), a), "{a} {k}");
                assert!(close(wrap_to_half_period_floor(shifted, p), a), "{a} {k}");
            }
        }
    }

    #[test]
    fn half_period_wrap_over_two_pi_is_wrap_angle_away_from_the_tie() {
        for a in [-7.0, -3.0, -1.0, 0.0, 0.5, 2.0, 3.1, 9.0] {
            assert!(close(wrap_to_half_period(a, TAU), wrap_angle(a)), "{a}");
        }
    }

    #[test]
    fn positive_wrap_lands_in_zero_to_period() {
        assert_eq!(wrap_positive(0.0, TAU), 0.0);
        assert_eq!(wrap_positive(TAU, TAU), 0.0);
        assert!(close(wrap_positive(-0.5 * PI, TAU), 1.5 * PI));
        assert!(close(wrap_positive(5.0 * PI, TAU), PI));
        assert!(close(wrap_positive(-0.25, 1.0), 0.75));
    }

    #[test]
    fn distance_is_symmetric_and_at_most_half_a_period() {
        assert!(close(distance(0.1, -0.1, TAU), 0.2));
        assert!(close(distance(-0.1, 0.1, TAU), 0.2));
        assert!(close(distance(PI - 0.1, -PI + 0.1, TAU), 0.2));
        assert!(close(distance(0.0, PI, TAU), PI));
        assert!(close(distance(0.3 + 4.0 * TAU, 0.3, TAU), 0.0));
        let quarter = 0.5 * PI;
        assert!(close(distance(0.1, quarter - 0.1, quarter), 0.2));
        assert!(close(distance(0.25 * PI, 0.0, quarter), 0.25 * PI));
    }
}
