//! Strict CDR decoding, fuzzed (issue 10): every message type kumi decodes is fed random byte
//! strings and mutations of valid encodings (bit flips, overwritten length fields, cuts,
//! insertions, deletions, appended bytes). No input may panic, and every accepted input must
//! re-encode, with the serializer RustDDS publishes with, to the same bytes outside its
//! padding (whose content CDR leaves undefined). Seeded: the same cases on every run.

use byteorder::LittleEndian;
use kumi_msgs::builtin_interfaces::Time;
use kumi_msgs::cdr::{decode_with_padding, from_bytes, ByteOrder};
use kumi_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
use kumi_msgs::geometry_msgs::{
    Point, Pose, PoseStamped, PoseWithCovariance, Quaternion, Transform, TransformStamped, Twist,
    TwistWithCovariance, Vector3,
};
use kumi_msgs::nav_msgs::Odometry;
use kumi_msgs::rosgraph_msgs::Clock;
use kumi_msgs::sensor_msgs::{Imu, JointState};
use kumi_msgs::std_msgs::{Bool, Float64, Float64MultiArray, Header, StringMsg};
use kumi_msgs::tf2_msgs::TFMessage;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Mutated cases per valid sample, and random byte strings per type.
const MUTATIONS: usize = 3000;
const RANDOM: usize = 2000;

fn encode<T: serde::Serialize>(value: &T) -> Vec<u8> {
    cdr_encoding::to_vec::<T, LittleEndian>(value).expect("kumi messages serialise")
}

fn text(rng: &mut ChaCha8Rng) -> String {
    let n = rng.random_range(0..12);
    (0..n)
        .map(|_| char::from(rng.random_range(b'a'..=b'z')))
        .collect()
}

fn header(rng: &mut ChaCha8Rng) -> Header {
    Header {
        stamp: Time {
            sec: rng.random(),
            nanosec: rng.random_range(0..1_000_000_000),
        },
        frame_id: text(rng),
    }
}

fn vector(rng: &mut ChaCha8Rng) -> Vector3 {
    Vector3 {
        x: rng.random(),
        y: rng.random(),
        z: rng.random(),
    }
}

fn pose(rng: &mut ChaCha8Rng) -> Pose {
    Pose {
        position: Point {
            x: rng.random(),
            y: rng.random(),
            z: rng.random(),
        },
        orientation: Quaternion {
            x: rng.random(),
            y: rng.random(),
            z: rng.random(),
            w: rng.random(),
        },
    }
}

fn floats(rng: &mut ChaCha8Rng) -> Vec<f64> {
    (0..rng.random_range(0..8)).map(|_| rng.random()).collect()
}

/// One mutation of `bytes`.
fn mutate(bytes: &[u8], rng: &mut ChaCha8Rng) -> Vec<u8> {
    let mut b = bytes.to_vec();
    let at = |rng: &mut ChaCha8Rng, len: usize| rng.random_range(0..len.max(1));
    match rng.random_range(0..7) {
        0 if !b.is_empty() => {
            let i = at(rng, b.len());
            b[i] ^= 1 << rng.random_range(0..8);
        }
        1 if b.len() >= 4 => {
            // A length field: small, zero, or huge.
            let i = at(rng, b.len() / 4) * 4;
            let v: u32 = match rng.random_range(0..3) {
                0 => 0,
                1 => rng.random_range(0..64),
                _ => rng.random(),
            };
            b[i..i + 4].copy_from_slice(&v.to_le_bytes());
        }
        2 => b.truncate(at(rng, b.len())),
        3 => {
            let i = at(rng, b.len() + 1).min(b.len());
            b.insert(i, rng.random());
        }
        4 if !b.is_empty() => {
            let i = at(rng, b.len());
            b.remove(i);
        }
        5 => b.extend((0..rng.random_range(1..9)).map(|_| rng.random::<u8>())),
        _ => {
            let i = at(rng, b.len());
            if i < b.len() {
                b[i] = 0;
            }
        }
    }
    b
}

/// Counts of one type's cases: (run, accepted).
fn fuzz<T>(name: &str, samples: Vec<T>, rng: &mut ChaCha8Rng) -> (usize, usize)
where
    T: serde::Serialize + serde::de::DeserializeOwned + PartialEq + std::fmt::Debug,
{
    let (mut run, mut accepted) = (0, 0);
    let check = |input: &[u8], run: &mut usize, accepted: &mut usize| {
        *run += 1;
        if let Ok((value, padding)) = decode_with_padding::<T>(input, ByteOrder::Little) {
            *accepted += 1;
            // The input with its padding zeroed, as the serializer writes it.
            let mut canonical = input.to_vec();
            for range in padding {
                canonical[range].fill(0);
            }
            let again = encode(&value);
            let rest = canonical.strip_prefix(again.as_slice()).unwrap_or_else(|| {
                panic!("{name}: accepted {input:?} re-encodes to {again:?} ({value:?})")
            });
            assert!(
                rest.len() < 4 && rest.iter().all(|b| *b == 0),
                "{name}: accepted {input:?} with {rest:?} after the message"
            );
        }
    };
    for sample in &samples {
        let bytes = encode(sample);
        let decoded: T = from_bytes(&bytes, ByteOrder::Little)
            .unwrap_or_else(|e| panic!("{name}: a valid encoding was refused: {e}"));
        assert_eq!(&decoded, sample, "{name}");
        for _ in 0..MUTATIONS {
            let input = mutate(&bytes, rng);
            check(&input, &mut run, &mut accepted);
        }
    }
    for _ in 0..RANDOM {
        let n = rng.random_range(0..64);
        let input: Vec<u8> = (0..n).map(|_| rng.random()).collect();
        check(&input, &mut run, &mut accepted);
    }
    eprintln!("{name}: {run} cases, {accepted} accepted");
    (run, accepted)
}

#[test]
fn no_input_panics_and_every_accepted_one_re_encodes_to_its_bytes() {
    let mut rng = ChaCha8Rng::seed_from_u64(10);
    let r = &mut rng;
    let mut total = 0;
    let n = 3;
    macro_rules! each {
        ($name:literal, $make:expr) => {{
            let samples = (0..n).map(|_| $make(&mut *r)).collect::<Vec<_>>();
            total += fuzz($name, samples, &mut *r).0;
        }};
    }
    each!("PoseStamped", |r: &mut ChaCha8Rng| PoseStamped {
        header: header(r),
        pose: pose(r),
    });
    each!("JointState", |r: &mut ChaCha8Rng| JointState {
        header: header(r),
        name: (0..r.random_range(0..4)).map(|_| text(r)).collect(),
        position: floats(r),
        velocity: floats(r),
        effort: floats(r),
    });
    each!("Float64MultiArray", |r: &mut ChaCha8Rng| {
        let data = floats(r);
        Float64MultiArray::vector(&text(r), data)
    });
    each!("Float64", |r: &mut ChaCha8Rng| Float64 { data: r.random() });
    each!("Clock", |r: &mut ChaCha8Rng| Clock {
        clock: Time {
            sec: r.random(),
            nanosec: r.random_range(0..1_000_000_000)
        }
    });
    each!("StringMsg", |r: &mut ChaCha8Rng| StringMsg {
        data: text(r)
    });
    each!("Bool", |r: &mut ChaCha8Rng| Bool { data: r.random() });
    each!("Imu", |r: &mut ChaCha8Rng| Imu {
        header: header(r),
        orientation: pose(r).orientation,
        orientation_covariance: [r.random(); 9],
        angular_velocity: vector(r),
        angular_velocity_covariance: [0.0; 9],
        linear_acceleration: vector(r),
        linear_acceleration_covariance: [1.0; 9],
    });
    each!("Odometry", |r: &mut ChaCha8Rng| Odometry {
        header: header(r),
        child_frame_id: text(r),
        pose: PoseWithCovariance {
            pose: pose(r),
            covariance: [r.random(); 36],
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: vector(r),
                angular: vector(r),
            },
            covariance: [0.0; 36],
        },
    });
    each!("TFMessage", |r: &mut ChaCha8Rng| TFMessage {
        transforms: (0..r.random_range(0..3))
            .map(|_| TransformStamped {
                header: header(r),
                child_frame_id: text(r),
                transform: Transform {
                    translation: vector(r),
                    rotation: pose(r).orientation,
                },
            })
            .collect(),
    });
    each!("DiagnosticArray", |r: &mut ChaCha8Rng| DiagnosticArray {
        header: header(r),
        status: (0..r.random_range(0..3))
            .map(|_| DiagnosticStatus {
                level: r.random_range(0..4),
                name: text(r),
                message: text(r),
                hardware_id: text(r),
                values: vec![KeyValue {
                    key: text(r),
                    value: text(r),
                }],
            })
            .collect(),
    });
    eprintln!("{total} cases in all");
    assert!(total > 100_000);
}
