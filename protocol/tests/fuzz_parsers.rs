//! Every parser of bytes that arrive from the network, fed mutations of valid messages and
//! random bytes: each returns a value or an error, never panics. Deterministic (a fixed
//! xorshift stream), so a failure reproduces.

use protocol::{parse_request, parse_service_request, sim};

struct Xorshift(u64);

impl Xorshift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const SEEDS: [&str; 8] = [
    r#"{"header":{"from":"ips","to":"ros","type":"instruction"},"body":{"command":"start","content":"hwState"}}"#,
    r#"{"header":{"from":"ips","to":"align","type":"request"},"body":{"command":"get","time_s":12.5}}"#,
    r#"{"header":{"from":"ips","to":"align","type":"request"},"body":{"command":"remove","ids":["3","4"]}}"#,
    r#"{"header":{"from":"ips","to":"align","type":"request"},"body":{"command":"align-cloud","cloud":"/d/scan.xyz","cloud_scale":0.001,"start_pose":{"xyz":[0.65,-0.22,0.02],"rpy":[0.0,0.0,0.25]},"delta_m":0.1}}"#,
    r#"{"header":{"from":"ips","to":"align","type":"request"},"body":{"command":"load","path":"s.json"}}"#,
    r#"{"command":"effects","joint_offsets":[0,0.001,0,0,0,0],"payload":{"mass_kg":0.4}}"#,
    r#"{"command":"motion","motion":{"kind":"path","waypoints":[{"time_s":1.0,"q":[0,0,0,0,0,0]}]}}"#,
    r#"{"command":"probe","mesh":"p.stl","base_from_part":{"xyz":[0,0,0],"rpy":[0,0,0]},"tcp":{"xyz":[0,0,0.15],"rpy":[0,0,0]},"tip_radius":0.003}"#,
];

/// Bytes JSON parsers find interesting.
const TOKENS: [&[u8]; 14] = [
    b"{",
    b"}",
    b"[",
    b"]",
    b"\"",
    b":",
    b",",
    b"null",
    b"1e400",
    b"-0",
    b"NaN",
    b"\\u0000",
    b"\xff",
    b"\"command\"",
];

fn mutate(seed: &[u8], rng: &mut Xorshift) -> Vec<u8> {
    let mut bytes = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(bytes.len() + 1);
        match rng.below(5) {
            0 if !bytes.is_empty() => {
                let index = at.min(bytes.len() - 1);
                bytes[index] ^= 1 << rng.below(8);
            }
            1 => bytes.truncate(at),
            2 => {
                let token = TOKENS[rng.below(TOKENS.len())];
                bytes.splice(at..at, token.iter().copied());
            }
            3 if at < bytes.len() => {
                let end = (at + 1 + rng.below(8)).min(bytes.len());
                bytes.drain(at..end);
            }
            _ => bytes.insert(at, (rng.next() >> 24) as u8),
        }
    }
    bytes
}

#[test]
fn mutated_and_random_messages_never_panic_a_parser() {
    let mut rng = Xorshift(0x9E37_79B9_7F4A_7C15);
    let (mut tried, mut accepted) = (0usize, 0usize);
    for round in 0..100_000 {
        let bytes = if round % 10 == 0 {
            (0..rng.below(300))
                .map(|_| (rng.next() >> 32) as u8)
                .collect()
        } else {
            mutate(SEEDS[rng.below(SEEDS.len())].as_bytes(), &mut rng)
        };
        tried += 1;
        accepted += usize::from(parse_request(&bytes).is_ok());
        accepted += usize::from(parse_service_request(&bytes).is_ok());
        accepted += usize::from(sim::parse_command(&bytes).is_ok());
    }
    assert_eq!(tried, 100_000);
    // Some mutations stay valid (a changed digit in a number): the parsers were exercised on
    // both sides.
    assert!(accepted > 100, "{accepted} accepted");
}
