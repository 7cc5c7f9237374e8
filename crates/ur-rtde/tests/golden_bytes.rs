//! Golden byte vectors written by hand from UR's RTDE guide: big-endian uint16 size (whole
//! package), uint8 type, payload.

#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use ur_rtde::{
    Package, ValueType, decode_values, encode_value, output_type, package, parse_setup_reply,
    recipe_names, setup_outputs_request,
};

#[test]
fn request_protocol_version_2() {
    // size 5 = 3 header + uint16 version 2; type 'V' = 0x56.
    let bytes = Package::new(
        package::REQUEST_PROTOCOL_VERSION,
        2u16.to_be_bytes().to_vec(),
    )
    .encode()
    .unwrap();
    assert_eq!(bytes, [0x00, 0x05, 0x56, 0x00, 0x02]);
}

#[test]
fn setup_outputs_v2_carries_the_frequency_as_a_double() {
    let bytes = setup_outputs_request(Some(125.0), &["timestamp", "actual_q"])
        .encode()
        .unwrap();
    // 125.0 as IEEE-754 double big-endian: 40 5F 40 00 00 00 00 00.
    let mut expected = vec![0x00, 3 + 8 + 18, b'O', 0x40, 0x5F, 0x40, 0, 0, 0, 0, 0];
    expected.extend_from_slice(b"timestamp,actual_q");
    assert_eq!(bytes, expected);
}

#[test]
fn setup_reply_v2_gives_recipe_and_types_with_not_found() {
    let mut payload = vec![1u8];
    payload.extend_from_slice(b"DOUBLE,VECTOR6D,NOT_FOUND,INT32");
    let reply = Package::new(package::CONTROL_PACKAGE_SETUP_OUTPUTS, payload);
    let (recipe, types) = parse_setup_reply(&reply, 2).unwrap();
    assert_eq!(recipe, 1);
    assert_eq!(
        types,
        vec![
            Some(ValueType::Double),
            Some(ValueType::Vector6d),
            None,
            Some(ValueType::Int32)
        ]
    );
    // Version 1 has no recipe id.
    let reply = Package::new(package::CONTROL_PACKAGE_SETUP_OUTPUTS, b"DOUBLE".to_vec());
    assert_eq!(
        parse_setup_reply(&reply, 1).unwrap(),
        (0, vec![Some(ValueType::Double)])
    );
}

#[test]
fn data_package_round_trip_with_exact_bytes() {
    let mut payload = vec![1u8]; // recipe id
    encode_value(ValueType::Double, &[1.5], &mut payload);
    encode_value(ValueType::Int32, &[-1.0], &mut payload);
    encode_value(ValueType::Uint32, &[7.0], &mut payload);
    assert_eq!(&payload[1..9], &[0x3F, 0xF8, 0, 0, 0, 0, 0, 0]);
    assert_eq!(&payload[9..13], &[0xFF, 0xFF, 0xFF, 0xFF]);
    assert_eq!(&payload[13..17], &[0, 0, 0, 7]);
    let values = decode_values(
        &payload,
        1,
        &[ValueType::Double, ValueType::Int32, ValueType::Uint32],
    )
    .unwrap();
    assert_eq!(values, vec![vec![1.5], vec![-1.0], vec![7.0]]);
    let short =
        decode_values(&payload[..10], 1, &[ValueType::Double, ValueType::Int32]).unwrap_err();
    assert_eq!(
        short.to_string(),
        "package of type 'U' is too short: 13 bytes needed, 10 present"
    );
}

#[test]
fn framing_reads_back_and_refuses_bad_sizes() {
    let package = Package::new(package::CONTROL_PACKAGE_START, vec![]);
    let bytes = package.encode().unwrap();
    assert_eq!(bytes, [0x00, 0x03, b'S']);
    assert_eq!(Package::read_from(&mut &bytes[..]).unwrap(), package);
    let error = Package::read_from(&mut &[0x00u8, 0x02, b'S'][..]).unwrap_err();
    assert_eq!(
        error.to_string(),
        "package size 2 is smaller than its 3-byte header"
    );
    assert!(Package::read_from(&mut &[0x00u8, 0x09, b'U', 1][..]).is_err());
}

#[test]
fn output_variable_types_follow_the_guide() {
    assert_eq!(output_type("actual_q"), Some(ValueType::Vector6d));
    assert_eq!(output_type("timestamp"), Some(ValueType::Double));
    assert_eq!(output_type("robot_mode"), Some(ValueType::Int32));
    assert_eq!(output_type("runtime_state"), Some(ValueType::Uint32));
    assert_eq!(output_type("joint_mode"), Some(ValueType::Vector6Int32));
    assert_eq!(
        output_type("output_double_register_12"),
        Some(ValueType::Double)
    );
    assert_eq!(output_type("output_double_register_48"), None);
    assert_eq!(output_type("no_such_variable"), None);
}

/// The recipe ur_rtde 1.6's RTDEReceiveInterface asks a 5.11 controller for when given no
/// variables, with the types UR's RTDE guide gives them. ur_rtde decodes data packages with its
/// own table of these types, so a wrong size here shifts every value after it.
#[test]
fn ur_rtde_default_receive_recipe_has_the_guide_types() {
    use ValueType::*;
    let expected: &[(&str, ValueType)] = &[
        ("timestamp", Double),
        ("target_q", Vector6d),
        ("target_qd", Vector6d),
        ("target_qdd", Vector6d),
        ("target_current", Vector6d),
        ("target_moment", Vector6d),
        ("actual_q", Vector6d),
        ("actual_qd", Vector6d),
        ("actual_current", Vector6d),
        ("joint_control_output", Vector6d),
        ("actual_TCP_pose", Vector6d),
        ("actual_TCP_speed", Vector6d),
        ("actual_TCP_force", Vector6d),
        ("target_TCP_pose", Vector6d),
        ("target_TCP_speed", Vector6d),
        ("actual_digital_input_bits", Uint64),
        ("joint_temperatures", Vector6d),
        ("actual_execution_time", Double),
        ("robot_mode", Int32),
        ("joint_mode", Vector6Int32),
        ("safety_mode", Int32),
        ("actual_tool_accelerometer", Vector3d),
        ("speed_scaling", Double),
        ("target_speed_fraction", Double),
        ("actual_momentum", Double),
        ("actual_main_voltage", Double),
        ("actual_robot_voltage", Double),
        ("actual_robot_current", Double),
        ("actual_joint_voltage", Vector6d),
        ("actual_digital_output_bits", Uint64),
        ("runtime_state", Uint32),
        ("standard_analog_input0", Double),
        ("standard_analog_input1", Double),
        ("standard_analog_output0", Double),
        ("standard_analog_output1", Double),
        ("robot_status_bits", Uint32),
        ("safety_status_bits", Uint32),
        ("ft_raw_wrench", Vector6d),
        ("payload", Double),
        ("payload_cog", Vector3d),
        ("payload_inertia", Vector6d),
        ("output_int_register_2", Int32),
        ("output_int_register_19", Int32),
        ("output_double_register_12", Double),
        ("output_double_register_19", Double),
    ];
    for (name, kind) in expected {
        assert_eq!(output_type(name), Some(*kind), "{name}");
    }
    assert_eq!(output_type("tool_output_voltage"), Some(Int32));
    assert_eq!(output_type("tool_mode"), Some(Uint32));
}

#[test]
fn a_trailing_comma_ends_the_name_list_instead_of_adding_an_empty_name() {
    // ur_rtde sends "timestamp,actual_q," (every name followed by a comma).
    assert_eq!(
        recipe_names("timestamp,actual_q,"),
        ["timestamp", "actual_q"]
    );
    assert_eq!(
        recipe_names("timestamp,actual_q"),
        ["timestamp", "actual_q"]
    );
    // Only the terminator is dropped: a real empty name is still there to be refused.
    assert_eq!(recipe_names("timestamp,,"), ["timestamp", ""]);
}
