//! FRI datagrams written out byte by byte from the protobuf encoding rules and the published
//! field numbers (header = 1, robot info = 2, monitor data = 3, connection info = 4; inside the
//! header: identifier = 1, sequence = 2, reflected sequence = 3; and so on), not produced by this
//! crate: they pin the wire format against the encoder and the decoder at once.

use kuka_fri::{
    COMMAND_MESSAGE_ID, CommandMessage, ConnectionInfo, ConnectionQuality, FriError,
    FriIoDirection, FriIoType, FriIoValue, JointValues, MONITORING_MESSAGE_ID, MessageHeader,
    MessageMonitorData, MonitoringMessage, SessionState, TimeStamp, encode,
};

/// A header-only command message: the answer of a monitoring client.
/// 0x0A = field 1 (header), length-delimited; 0x08 = identifier varint 0x34001 = 81 80 0D;
/// 0x10 = sequence 7; 0x18 = reflected sequence 42 (0x2A).
const MONITORING_REPLY: [u8; 10] = [0x0A, 0x08, 0x08, 0x81, 0x80, 0x0D, 0x10, 0x07, 0x18, 0x2A];

#[rustfmt::skip]
const MONITORING_MESSAGE: [u8; 53] = [
    // header: identifier 0x245142 (varint C2 A2 91 01), sequence 1, reflected 0
    0x0A, 0x09, 0x08, 0xC2, 0xA2, 0x91, 0x01, 0x10, 0x01, 0x18, 0x00,
    // monitor data (field 3), 30 bytes
    0x1A, 0x1E,
    //   measured joint position (field 1), 18 bytes: two unpacked fixed64 values 0.5 and -1.0
    0x0A, 0x12,
    0x09, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xE0, 0x3F,
    0x09, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF0, 0xBF,
    //   time stamp (field 15 -> tag 0x7A): sec 12, nanosec 500 000 000 (varint 80 CA B5 EE 01)
    0x7A, 0x08, 0x08, 0x0C, 0x10, 0x80, 0xCA, 0xB5, 0xEE, 0x01,
    // connection info (field 4): MONITORING_READY (2), GOOD (2), send period 5 ms, multiplier 1
    0x22, 0x08, 0x08, 0x02, 0x10, 0x02, 0x18, 0x05, 0x20, 0x01,
];

fn monitoring_message() -> MonitoringMessage {
    MonitoringMessage {
        header: MessageHeader {
            message_identifier: MONITORING_MESSAGE_ID,
            sequence_counter: 1,
            reflected_sequence_counter: 0,
        },
        robot_info: None,
        monitor_data: Some(MessageMonitorData {
            measured_joint_position: Some(JointValues {
                value: vec![0.5, -1.0],
            }),
            timestamp: Some(TimeStamp {
                sec: 12,
                nanosec: 500_000_000,
            }),
            ..MessageMonitorData::default()
        }),
        connection_info: Some(ConnectionInfo {
            session_state: SessionState::MonitoringReady as i32,
            quality: ConnectionQuality::Good as i32,
            send_period_ms: Some(5),
            receive_multiplier: Some(1),
        }),
        end_of_message_data: None,
    }
}

#[test]
fn monitoring_reply_matches_the_hand_encoded_bytes() {
    let reply = CommandMessage::monitoring_reply(7, 42);
    assert_eq!(encode(&reply), MONITORING_REPLY);
    let decoded = CommandMessage::decode_checked(&MONITORING_REPLY).expect("decodes");
    assert_eq!(decoded.header.message_identifier, COMMAND_MESSAGE_ID);
    assert_eq!(decoded.header.sequence_counter, 7);
    assert_eq!(decoded.header.reflected_sequence_counter, 42);
    assert!(decoded.command_data.is_none());
}

#[test]
fn monitoring_message_matches_the_hand_encoded_bytes() {
    assert_eq!(encode(&monitoring_message()), MONITORING_MESSAGE);
    let decoded = MonitoringMessage::decode_checked(&MONITORING_MESSAGE).expect("decodes");
    assert_eq!(decoded, monitoring_message());
    assert_eq!(decoded.measured_positions(), Some(&[0.5, -1.0][..]));
    assert_eq!(decoded.controller_time_s(), Some(12.5));
    assert_eq!(decoded.session_state(), Some(SessionState::MonitoringReady));
    assert_eq!(decoded.quality(), Some(ConnectionQuality::Good));
    assert_eq!(decoded.send_period_s(), Some(0.005));
    assert_eq!(decoded.receive_multiplier(), 1);
}

#[test]
fn packed_joint_values_decode_too() {
    // field 1, length-delimited, 16 bytes: the packed form of [0.5, -1.0].
    let packed = [
        0x0A, 0x10, 0, 0, 0, 0, 0, 0, 0xE0, 0x3F, 0, 0, 0, 0, 0, 0, 0xF0, 0xBF,
    ];
    let values = <JointValues as prost::Message>::decode(&packed[..]).expect("decodes");
    assert_eq!(values.value, vec![0.5, -1.0]);
}

#[test]
fn unknown_fields_are_skipped() {
    // The monitoring message plus an IPO data field (5) this crate does not model:
    // tracking performance (field 12, fixed64) 1.0.
    let mut bytes = MONITORING_MESSAGE.to_vec();
    bytes.extend_from_slice(&[0x2A, 0x09, 0x61, 0, 0, 0, 0, 0, 0, 0xF0, 0x3F]);
    let decoded = MonitoringMessage::decode_checked(&bytes).expect("decodes");
    assert_eq!(decoded, monitoring_message());
}

#[test]
fn a_command_message_is_not_taken_for_a_monitoring_message() {
    let error = MonitoringMessage::decode_checked(&MONITORING_REPLY).expect_err("refused");
    assert_eq!(
        error,
        FriError::WrongIdentifier {
            found: COMMAND_MESSAGE_ID,
            expected: MONITORING_MESSAGE_ID
        }
    );
}

#[test]
fn garbage_and_oversized_datagrams_are_refused() {
    assert!(matches!(
        MonitoringMessage::decode_checked(&[0xFF, 0xFF, 0xFF]),
        Err(FriError::Decode(_))
    ));
    // A message without its header: protobuf decoders default a missing required field, so
    // the identifier check is what refuses it.
    assert!(matches!(
        MonitoringMessage::decode_checked(&[0x22, 0x02, 0x08, 0x02]),
        Err(FriError::WrongIdentifier { found: 0, .. })
    ));
    assert!(matches!(
        MonitoringMessage::decode_checked(&[0u8; 2000]),
        Err(FriError::TooLarge(2000))
    ));
}

/// The monitor data with two IOs the Sunrise application registered for FRI: readIORequest is
/// field 8 of the monitor data; in each value name = 1, type = 2, direction = 3, digital value
/// = 4 (varint), analog value = 5 (fixed64), as the FRI client SDKs 1.13-2.5 number them.
#[rustfmt::skip]
const MONITOR_DATA_WITH_IO: [u8; 33] = [
    // readIORequest (field 8 -> tag 0x42), 11 bytes: "P.T", BOOLEAN (0), INPUT (0), value 1
    0x42, 0x0B, 0x0A, 0x03, b'P', b'.', b'T', 0x10, 0x00, 0x18, 0x00, 0x20, 0x01,
    // readIORequest, 18 bytes: "A.V", ANALOG (2), OUTPUT (1), analog value 0.5 (fixed64)
    0x42, 0x12, 0x0A, 0x03, b'A', b'.', b'V', 0x10, 0x02, 0x18, 0x01,
    0x29, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xE0, 0x3F,
];

#[test]
fn io_values_match_the_hand_encoded_bytes() {
    let data = MessageMonitorData {
        read_io_request: vec![
            FriIoValue::boolean_input("P.T", true),
            FriIoValue {
                name: "A.V".to_owned(),
                io_type: FriIoType::Analog as i32,
                direction: FriIoDirection::Output as i32,
                digital_value: None,
                analog_value: Some(0.5),
            },
        ],
        ..MessageMonitorData::default()
    };
    assert_eq!(encode(&data), MONITOR_DATA_WITH_IO);
    let decoded =
        <MessageMonitorData as prost::Message>::decode(&MONITOR_DATA_WITH_IO[..]).expect("decodes");
    assert_eq!(decoded, data);
    assert_eq!(decoded.read_io_request[0].is_set(), Some(true));
    // An analog IO is not a switch.
    assert_eq!(decoded.read_io_request[1].is_set(), None);
}
