//! Real UR factory calibrations, as published: the deltas to the nominal DH table in the
//! calibration tests of Universal Robots' ROS drivers (`ur_calibration/test/calibration_test.cpp`
//! in Universal_Robots_ROS_Driver and Universal_Robots_ROS2_Driver). Set A is there applied to a
//! UR10, sets B and C to a UR10e. The numbers are kept digit for digit.

use crate::kinematics::DhTable;
use crate::robots::ShippedRobot;

/// One published calibration: its name, the robot it belongs to and its deltas.
#[derive(Debug, Clone, PartialEq)]
pub struct PublishedCalibration {
    pub name: &'static str,
    pub robot: ShippedRobot,
    pub delta: DhTable,
}

impl PublishedCalibration {
    /// The calibrated table: the robot's nominal one plus the deltas.
    pub fn calibrated(&self) -> Option<DhTable> {
        self.robot.nominal_dh()?.plus(&self.delta).ok()
    }

    /// As a calibration file (`ips demo --calibration`, `sim-robot --calibration`).
    pub fn file_text(&self) -> String {
        let row = |values: &[f64]| {
            let numbers: Vec<String> = values.iter().map(|v| format!("{v:?}")).collect();
            format!("[{}]", numbers.join(", "))
        };
        format!(
            "{{\"dh_delta\": {{\"theta\": {}, \"a\": {}, \"d\": {}, \"alpha\": {}}}}}",
            row(&self.delta.theta),
            row(&self.delta.a),
            row(&self.delta.d),
            row(&self.delta.alpha)
        )
    }
}

/// Sets A (UR10), B and C (UR10e), in that order.
#[allow(clippy::excessive_precision)] // As published.
pub fn ur_driver_calibrations() -> Vec<PublishedCalibration> {
    let table = |theta: [f64; 6], a: [f64; 6], d: [f64; 6], alpha: [f64; 6]| DhTable {
        theta: theta.to_vec(),
        a: a.to_vec(),
        d: d.to_vec(),
        alpha: alpha.to_vec(),
    };
    vec![
        PublishedCalibration {
            name: "A",
            robot: ShippedRobot::Ur10,
            delta: table(
                [
                    -7.290070070824746e-05,
                    -0.01713897289704999,
                    -0.03707159413492756,
                    0.054279462160583214,
                    1.488984257025741e-07,
                    1.551499479707493e-05,
                ],
                [
                    4.6311376834935676e-05,
                    -0.00012568315331862312,
                    0.00186216581161458,
                    9.918593870679266e-05,
                    4.215462720453189e-06,
                    0.0,
                ],
                [
                    0.00065609212979853,
                    1.4442162376284788,
                    0.854147723854608,
                    -2.2989425877563705,
                    -1.573498686836816e-05,
                    1.9072435590711256e-05,
                ],
                [
                    0.000211987863869334,
                    -0.0072553625957652995,
                    -0.013483226769541364,
                    0.0013495820227329425,
                    -0.001263136163679901,
                    0.0,
                ],
            ),
        },
        PublishedCalibration {
            name: "B",
            robot: ShippedRobot::Ur10e,
            delta: table(
                [
                    1.59613525316931737e-07,
                    -0.917209621528830232,
                    7.12936131346499469,
                    0.0710299029424392298,
                    -1.64258976526054923e-06,
                    9.17286101034808787e-08,
                ],
                [
                    0.000108651068627930392,
                    0.240324175250532346,
                    0.00180628180213493472,
                    2.63076149165684402e-05,
                    3.96638632500012715e-06,
                    0.0,
                ],
                [
                    -0.000144894975118076141,
                    303.469135666158195,
                    -309.88394307789747,
                    6.41459904397394975,
                    -4.48232900190081995e-05,
                    -0.00087071402790364627,
                ],
                [
                    -0.000444781952841921679,
                    -0.00160215112531214153,
                    0.00631917793331091861,
                    -0.00165055247340828437,
                    0.000763682515545038854,
                    0.0,
                ],
            ),
        },
        PublishedCalibration {
            name: "C",
            robot: ShippedRobot::Ur10e,
            delta: table(
                [
                    -2.41478068943590252e-07,
                    1.60233952386694556,
                    -1.68607190752171299,
                    0.0837331147700118711,
                    -1.01260355871157781e-07,
                    3.91986209186123702e-08,
                ],
                [
                    2.12234865571205891e-05,
                    0.632017132627700651,
                    0.00229833638891230319,
                    -4.61409023720933908e-05,
                    -6.39280053471801522e-05,
                    0.0,
                ],
                [
                    -0.000160188285741325043,
                    439.140974079900957,
                    -446.027059806332147,
                    6.88618689642360149,
                    -3.86588496858186748e-05,
                    -0.00087908274257374186,
                ],
                [
                    -0.000650246557584166496,
                    0.00139416666825590402,
                    0.00693818880325995126,
                    -0.000811641562390219562,
                    0.000411120504570705592,
                    0.0,
                ],
            ),
        },
    ]
}

/// The published calibration named `name`.
pub fn ur_driver_calibration(name: &str) -> Option<PublishedCalibration> {
    ur_driver_calibrations()
        .into_iter()
        .find(|c| c.name == name)
}
