//! A UR robot's factory calibration: the calibrated DH table its controller reports (the
//! primary interface's KINEMATICS_INFO), as robot-bridge passes it on in its `status` reply, and
//! the calibration file `ips demo --calibration` and `sim-robot --calibration` read (DESIGN.md
//! 6.4): `{"dh_delta": {"theta": [6], "a": [6], "d": [6], "alpha": [6]}}`, rad and m, the deltas
//! the controller adds to the nominal table.

use serde::{Deserialize, Serialize};

/// The controller's calibrated DH table, rad and m: `status`'s `kinematics`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControllerKinematics {
    pub dh_theta: Vec<f64>,
    pub dh_a: Vec<f64>,
    pub dh_d: Vec<f64>,
    pub dh_alpha: Vec<f64>,
    /// The hash UR's ROS drivers compare (`calib_<n>`), so a cell can tell which calibration a
    /// kinematics file was made from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hash: Option<String>,
}

impl ControllerKinematics {
    /// Six finite values per row, or what is wrong.
    pub fn check(&self) -> Result<(), String> {
        check_rows(&[
            ("dh_theta", &self.dh_theta),
            ("dh_a", &self.dh_a),
            ("dh_d", &self.dh_d),
            ("dh_alpha", &self.dh_alpha),
        ])
    }
}

/// The calibration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationFile {
    pub dh_delta: DhDelta,
}

/// Deltas to the nominal DH table, rad and m (d may be hundreds of metres: UR calibrations move
/// the parallel joints' common normals along their axes and cancel the offsets).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DhDelta {
    pub theta: Vec<f64>,
    pub a: Vec<f64>,
    pub d: Vec<f64>,
    pub alpha: Vec<f64>,
}

impl CalibrationFile {
    /// Parses and checks a calibration file's text: every key present, six finite numbers each.
    pub fn parse(text: &str) -> Result<Self, String> {
        let file: CalibrationFile = serde_json::from_str(text).map_err(|error| {
            format!(
                "not a calibration file ({error}); expected {{\"dh_delta\": {{\"theta\": [6 rad], \"a\": [6 m], \"d\": [6 m], \"alpha\": [6 rad]}}}}"
            )
        })?;
        let delta = &file.dh_delta;
        check_rows(&[
            ("dh_delta.theta", &delta.theta),
            ("dh_delta.a", &delta.a),
            ("dh_delta.d", &delta.d),
            ("dh_delta.alpha", &delta.alpha),
        ])?;
        Ok(file)
    }
}

fn check_rows(rows: &[(&str, &Vec<f64>)]) -> Result<(), String> {
    for (name, row) in rows {
        if row.len() != 6 {
            return Err(format!(
                "{name} has {} values; a UR arm has 6 joints",
                row.len()
            ));
        }
        if let Some((joint, value)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(format!("{name}[{joint}] is not a finite number ({value})"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_calibration_file_parses_and_bad_ones_say_what_is_wrong() {
        let good = r#"{"dh_delta": {"theta": [0,1e-4,0,0,0,0], "a": [0,0,0,0,0,0],
            "d": [0,439.1,-446.0,6.9,0,0], "alpha": [0,0,0,0,0,0]}}"#;
        let file = CalibrationFile::parse(good).unwrap();
        assert_eq!(file.dh_delta.d[1], 439.1);
        let five = good.replace("\"a\": [0,0,0,0,0,0]", "\"a\": [0,0,0,0,0]");
        assert!(
            CalibrationFile::parse(&five)
                .unwrap_err()
                .contains("dh_delta.a has 5 values")
        );
        let missing = good.replace("\"alpha\": [0,0,0,0,0,0]", "\"alfa\": [0,0,0,0,0,0]");
        let error = CalibrationFile::parse(&missing).unwrap_err();
        assert!(error.contains("alfa") || error.contains("alpha"), "{error}");
        // JSON has no NaN: a string or null where a number belongs is refused by the parser.
        let nan = good.replace("\"theta\": [0,", "\"theta\": [null,");
        assert!(
            CalibrationFile::parse(&nan)
                .unwrap_err()
                .contains("not a calibration file")
        );
        let huge = good.replace("\"theta\": [0,", "\"theta\": [1e999,");
        assert!(CalibrationFile::parse(&huge).is_err());
        assert!(CalibrationFile::parse("[1,2,3]").is_err());
        let kinematics = ControllerKinematics {
            dh_theta: vec![0.0; 6],
            dh_a: vec![0.0; 6],
            dh_d: vec![f64::NAN; 6],
            dh_alpha: vec![0.0; 6],
            hash: None,
        };
        assert!(kinematics.check().unwrap_err().contains("dh_d[0]"));
    }
}
