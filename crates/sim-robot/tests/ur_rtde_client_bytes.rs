//! sim-robot's RTDE server against the exact requests ur_rtde's RTDEReceiveInterface sends (its
//! default recipe, a name list ending in a comma), spoken as raw packages: the regression test
//! for the segfault ur_rtde hit when the server answered one NOT_FOUND per trailing comma.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::net::TcpStream;
use std::time::Duration;

use align_core::robots::ShippedRobot;
use ur_rtde::{Package, ValueType, decode_values, package, parse_setup_reply};

/// ur_rtde 1.6's default receive recipe for a 5.11 controller, in its order.
const UR_RTDE_DEFAULT_RECIPE: &[&str] = &[
    "timestamp",
    "target_q",
    "target_qd",
    "target_qdd",
    "target_current",
    "target_moment",
    "actual_q",
    "actual_qd",
    "actual_current",
    "joint_control_output",
    "actual_TCP_pose",
    "actual_TCP_speed",
    "actual_TCP_force",
    "target_TCP_pose",
    "target_TCP_speed",
    "actual_digital_input_bits",
    "joint_temperatures",
    "actual_execution_time",
    "robot_mode",
    "joint_mode",
    "safety_mode",
    "actual_tool_accelerometer",
    "speed_scaling",
    "target_speed_fraction",
    "actual_momentum",
    "actual_main_voltage",
    "actual_robot_voltage",
    "actual_robot_current",
    "actual_joint_voltage",
    "actual_digital_output_bits",
    "runtime_state",
    "standard_analog_input0",
    "standard_analog_input1",
    "standard_analog_output0",
    "standard_analog_output1",
    "robot_status_bits",
    "safety_status_bits",
    "ft_raw_wrench",
    "payload",
    "payload_cog",
    "payload_inertia",
    "output_int_register_2",
    "output_int_register_12",
    "output_int_register_13",
    "output_int_register_14",
    "output_int_register_15",
    "output_int_register_16",
    "output_int_register_17",
    "output_int_register_18",
    "output_int_register_19",
    "output_double_register_12",
    "output_double_register_13",
    "output_double_register_14",
    "output_double_register_15",
    "output_double_register_16",
    "output_double_register_17",
    "output_double_register_18",
    "output_double_register_19",
];

fn exchange(stream: &mut TcpStream, request: Package) -> Package {
    request.write_to(stream).unwrap();
    Package::read_from(stream).unwrap()
}

#[test]
fn ur_rtde_default_recipe_with_trailing_comma_is_set_up_and_streamed() {
    let sim = sim_robot::start(&sim_robot::Config {
        robot: ShippedRobot::Ur10e,
        rtde_listen: "127.0.0.1:0".to_owned(),
        primary_listen: None,
        calibration: None,
        control: "tcp://127.0.0.1:*".to_owned(),
        fri: sim_robot::FriSettings::default(),
    })
    .unwrap();
    let mut stream = TcpStream::connect(sim.rtde_address.as_deref().unwrap()).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();

    let accepted = exchange(
        &mut stream,
        Package::new(package::REQUEST_PROTOCOL_VERSION, vec![0, 2]),
    );
    assert_eq!(accepted.payload, [1]);

    // As ur_rtde builds it: frequency, then every name followed by a comma.
    let mut setup = 500.0f64.to_be_bytes().to_vec();
    for name in UR_RTDE_DEFAULT_RECIPE {
        setup.extend_from_slice(name.as_bytes());
        setup.push(b',');
    }
    let reply = exchange(
        &mut stream,
        Package::new(package::CONTROL_PACKAGE_SETUP_OUTPUTS, setup),
    );
    let (recipe, types) = parse_setup_reply(&reply, 2).unwrap();
    assert_eq!(
        recipe,
        1,
        "{}",
        String::from_utf8_lossy(&reply.payload[1..])
    );
    assert_eq!(types.len(), UR_RTDE_DEFAULT_RECIPE.len());
    let types: Vec<ValueType> = types.into_iter().map(Option::unwrap).collect();

    // The start reply comes first, before any data package.
    let started = exchange(
        &mut stream,
        Package::new(package::CONTROL_PACKAGE_START, vec![]),
    );
    assert_eq!(
        (started.kind, started.payload),
        (package::CONTROL_PACKAGE_START, vec![1])
    );

    let data = Package::read_from(&mut stream).unwrap();
    assert_eq!(data.kind, package::DATA_PACKAGE);
    let expected_len = 1 + types.iter().map(|t| t.size()).sum::<usize>();
    assert_eq!(data.payload.len(), expected_len);
    let values = decode_values(&data.payload, 1, &types).unwrap();
    let value = |name: &str| {
        let index = UR_RTDE_DEFAULT_RECIPE
            .iter()
            .position(|n| *n == name)
            .unwrap();
        values[index].clone()
    };
    assert_eq!(value("actual_q"), sim_robot::home(ShippedRobot::Ur10e));
    assert!(value("timestamp")[0] > 0.0);
    assert_eq!(value("robot_mode"), [7.0]);
    // At rest the accelerometer reads 1 g.
    let accelerometer = value("actual_tool_accelerometer");
    let g = accelerometer.iter().map(|a| a * a).sum::<f64>().sqrt();
    assert!((g - 9.80665).abs() < 1e-9, "{accelerometer:?}");
    sim.stop();
}
