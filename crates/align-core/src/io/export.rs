//! The aligned part pose written in the formats a cell's other software reads (DESIGN.md 6.4):
//! a URDF or SDF model to place the part in a simulator, a `static_transform_publisher` line for
//! ROS 2, a KUKA KRL FRAME, a URScript pose, and a CSV of the touches. Every pose is
//! `base_from_part`, relative to the robot's base frame.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::str::FromStr;

use nalgebra::Isometry3;

use crate::pose::xyz_rpy;

/// A format the pose can be written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFormat {
    Urdf,
    Sdf,
    RosTf,
    KukaBase,
    UrPose,
    Csv,
}

impl ExportFormat {
    pub const ALL: [ExportFormat; 6] = [
        ExportFormat::Urdf,
        ExportFormat::Sdf,
        ExportFormat::RosTf,
        ExportFormat::KukaBase,
        ExportFormat::UrPose,
        ExportFormat::Csv,
    ];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ExportFormat::Urdf => "urdf",
            ExportFormat::Sdf => "sdf",
            ExportFormat::RosTf => "ros-tf",
            ExportFormat::KukaBase => "kuka-base",
            ExportFormat::UrPose => "ur-pose",
            ExportFormat::Csv => "csv",
        }
    }
}

impl FromStr for ExportFormat {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|format| format.name() == text)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|f| f.name()).collect();
                format!(
                    "unknown export format '{text}' (expected one of {})",
                    names.join(", ")
                )
            })
    }
}

/// The part's mesh, for the model formats' geometry.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportMesh {
    /// Absolute path of the mesh file.
    pub path: PathBuf,
    /// The file's unit in metres (0.001 for a mesh in mm).
    pub scale: f64,
}

/// One touch for the CSV: its ball centre in the base frame and its signed residual.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportRow {
    pub id: String,
    pub ball_centre_m: [f64; 3],
    pub residual_m: f64,
}

/// What an export writes.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseExport<'a> {
    /// The robot base frame's name (the session's `base_link`).
    pub base_frame: &'a str,
    pub base_from_part: Isometry3<f64>,
    /// The part's mesh, when known, for the URDF's and SDF's visual and collision geometry.
    pub mesh: Option<ExportMesh>,
    /// The touches, for the CSV.
    pub rows: &'a [ExportRow],
}

/// The child frame's name in every format.
const PART_FRAME: &str = "part";

/// Writes `export` in `format`, ending in a newline. `Err` when the pose is not finite, the base
/// frame has no name, or the CSV has no touches to list.
pub fn render(format: ExportFormat, export: &PoseExport) -> Result<String, String> {
    let (xyz, rpy) = xyz_rpy(&export.base_from_part);
    if !xyz.iter().chain(&rpy).all(|v| v.is_finite()) {
        return Err("the pose to export is not finite".to_owned());
    }
    if export.base_frame.trim().is_empty() {
        return Err("the base frame to export relative to has no name".to_owned());
    }
    Ok(match format {
        ExportFormat::Urdf => urdf(export, xyz, rpy),
        ExportFormat::Sdf => sdf(export, xyz, rpy),
        ExportFormat::RosTf => ros_tf(export, xyz),
        ExportFormat::KukaBase => kuka_frame(xyz, rpy),
        ExportFormat::UrPose => ur_pose(&export.base_from_part),
        ExportFormat::Csv => csv(export.rows)?,
    })
}

/// Metres and radians to the nanometre and nanoradian: below anything a robot cell resolves,
/// without the 17-digit tails of a shortest round-trip print.
fn fixed(value: f64) -> String {
    format!("{:.9}", without_negative_zero(value, 9))
}

/// `value` rounded to `decimals`, so that -1e-17 prints as 0.000, not -0.000.
fn without_negative_zero(value: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    let rounded = (value * scale).round() / scale;
    if rounded == 0.0 { 0.0 } else { value }
}

fn joined(values: &[f64]) -> String {
    values
        .iter()
        .map(|v| fixed(*v))
        .collect::<Vec<_>>()
        .join(" ")
}

/// `text` safe inside XML or HTML text and attribute values.
pub fn xml_escaped(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            _ => out.push(c),
        }
    }
    out
}

/// `file://` URI of a mesh path (absolute paths; characters URIs reserve are percent-encoded).
fn file_uri(mesh: &ExportMesh) -> String {
    let mut uri = String::from("file://");
    for byte in mesh.path.to_string_lossy().bytes() {
        if byte.is_ascii_alphanumeric() || b"/-._~".contains(&byte) {
            uri.push(byte as char);
        } else {
            let _ = write!(uri, "%{byte:02X}");
        }
    }
    uri
}

fn urdf(export: &PoseExport, xyz: [f64; 3], rpy: [f64; 3]) -> String {
    let base = xml_escaped(export.base_frame);
    let geometry = export.mesh.as_ref().map_or(String::new(), |mesh| {
        let shape = format!(
            "<geometry><mesh filename=\"{}\" scale=\"{}\"/></geometry>",
            xml_escaped(&file_uri(mesh)),
            joined(&[mesh.scale; 3])
        );
        format!("\n    <visual>{shape}</visual>\n    <collision>{shape}</collision>\n  ")
    });
    format!(
        "<?xml version=\"1.0\"?>\n\
         <!-- The aligned part: base_from_part, relative to the robot base frame '{base}'. -->\n\
         <robot name=\"aligned_part\">\n  \
         <link name=\"{base}\"/>\n  \
         <link name=\"{PART_FRAME}\">{geometry}</link>\n  \
         <joint name=\"part_joint\" type=\"fixed\">\n    \
         <parent link=\"{base}\"/>\n    \
         <child link=\"{PART_FRAME}\"/>\n    \
         <origin xyz=\"{}\" rpy=\"{}\"/>\n  \
         </joint>\n\
         </robot>\n",
        joined(&xyz),
        joined(&rpy)
    )
}

fn sdf(export: &PoseExport, xyz: [f64; 3], rpy: [f64; 3]) -> String {
    let geometry = export.mesh.as_ref().map_or(String::new(), |mesh| {
        let shape = format!(
            "<geometry><mesh><uri>{}</uri><scale>{}</scale></mesh></geometry>",
            xml_escaped(&file_uri(mesh)),
            joined(&[mesh.scale; 3])
        );
        format!(
            "\n      <visual name=\"visual\">{shape}</visual>\n      <collision name=\"collision\">{shape}</collision>\n    "
        )
    });
    format!(
        "<?xml version=\"1.0\"?>\n\
         <!-- The aligned part: base_from_part, relative to the robot base frame '{}'. -->\n\
         <sdf version=\"1.9\">\n  \
         <model name=\"{PART_FRAME}\">\n    \
         <static>true</static>\n    \
         <pose>{} {}</pose>\n    \
         <link name=\"{PART_FRAME}\">{geometry}</link>\n  \
         </model>\n\
         </sdf>\n",
        xml_escaped(export.base_frame),
        joined(&xyz),
        joined(&rpy)
    )
}

/// A word for a POSIX shell: as it is when it needs no quoting, else in single quotes.
fn shell_word(text: &str) -> String {
    if !text.is_empty()
        && text
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_-./:".contains(c))
    {
        text.to_owned()
    } else {
        format!("'{}'", text.replace('\'', r"'\''"))
    }
}

fn ros_tf(export: &PoseExport, xyz: [f64; 3]) -> String {
    let q = export.base_from_part.rotation.coords;
    // A quaternion and its negation are the same rotation; print the one with w >= 0.
    let sign = if q.w < 0.0 { -1.0 } else { 1.0 };
    format!(
        "ros2 run tf2_ros static_transform_publisher --x {} --y {} --z {} --qx {} --qy {} --qz {} --qw {} --frame-id {} --child-frame-id {PART_FRAME}\n",
        fixed(xyz[0]),
        fixed(xyz[1]),
        fixed(xyz[2]),
        fixed(sign * q.x),
        fixed(sign * q.y),
        fixed(sign * q.z),
        fixed(sign * q.w),
        shell_word(export.base_frame)
    )
}

/// KRL FRAME: mm and degrees, `R = Rz(A) Ry(B) Rx(C)`, which is URDF's rpy with A = yaw,
/// B = pitch, C = roll. Four decimals: KRL's REAL is a 32-bit float, which holds no more for a
/// position of a metre or more.
fn kuka_frame(xyz: [f64; 3], rpy: [f64; 3]) -> String {
    let mm = xyz.map(|v| without_negative_zero(v * 1e3, 4));
    let degrees = rpy.map(|v| without_negative_zero(v.to_degrees(), 4));
    format!(
        "{{X {:.4},Y {:.4},Z {:.4},A {:.4},B {:.4},C {:.4}}}\n",
        mm[0], mm[1], mm[2], degrees[2], degrees[1], degrees[0]
    )
}

/// URScript pose: metres and a rotation vector (axis times angle, rad), as `p[...]`.
fn ur_pose(pose: &Isometry3<f64>) -> String {
    let t = pose.translation.vector;
    let r = pose.rotation.scaled_axis();
    format!(
        "p[{}, {}, {}, {}, {}, {}]\n",
        fixed(t.x),
        fixed(t.y),
        fixed(t.z),
        fixed(r.x),
        fixed(r.y),
        fixed(r.z)
    )
}

/// RFC 4180 field: quoted when it holds a comma, a quote or a line break.
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_owned()
    }
}

fn csv(rows: &[ExportRow]) -> Result<String, String> {
    if rows.is_empty() {
        return Err("there are no touches to write as CSV".to_owned());
    }
    let mut text = String::from("id,x_m,y_m,z_m,residual_m\n");
    for row in rows {
        let [x, y, z] = row.ball_centre_m;
        let _ = writeln!(
            text,
            "{},{},{},{},{}",
            csv_field(&row.id),
            fixed(x),
            fixed(y),
            fixed(z),
            fixed(row.residual_m)
        );
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::isometry_from_xyz_rpy;
    use nalgebra::{UnitQuaternion, Vector3};

    fn pose() -> Isometry3<f64> {
        isometry_from_xyz_rpy([0.6123456, -0.25, 0.02], [0.1, -0.4, 2.9])
    }

    fn export(rows: &[ExportRow]) -> PoseExport<'_> {
        PoseExport {
            base_frame: "base_link",
            base_from_part: pose(),
            mesh: None,
            rows,
        }
    }

    /// Reads the numbers of a `{X x,Y y,...}` or `p[...]` literal, in order.
    fn numbers(text: &str) -> Vec<f64> {
        text.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
            .filter(|s| !s.is_empty() && s.chars().any(|c| c.is_ascii_digit()))
            .map(|s| s.parse().unwrap())
            .collect()
    }

    #[test]
    fn kuka_frame_round_trips_through_zyx_euler_angles() {
        let text = render(ExportFormat::KukaBase, &export(&[])).unwrap();
        assert!(
            text.starts_with("{X 612.3456,Y -250.0000,Z 20.0000,A "),
            "{text}"
        );
        let v = numbers(&text);
        let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), v[3].to_radians())
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), v[4].to_radians())
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), v[5].to_radians());
        let original = pose();
        // Four decimals of a degree: 0.87 urad at most per angle.
        assert!(rotation.angle_to(&original.rotation) < 3e-6);
        let position = Vector3::new(v[0], v[1], v[2]) / 1e3;
        assert!((position - original.translation.vector).norm() < 1e-7);
    }

    #[test]
    fn ur_pose_round_trips_through_the_rotation_vector() {
        let text = render(ExportFormat::UrPose, &export(&[])).unwrap();
        assert!(text.starts_with("p[0.612345600, -0.250000000, 0.020000000, "));
        let v = numbers(&text);
        let rotation = UnitQuaternion::from_scaled_axis(Vector3::new(v[3], v[4], v[5]));
        assert!(rotation.angle_to(&pose().rotation) < 1e-8);
    }

    #[test]
    fn ros_tf_quaternion_is_the_rotation() {
        let text = render(ExportFormat::RosTf, &export(&[])).unwrap();
        let v = numbers(&text.replace("tf2_ros", "").replace("ros2", ""));
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(v[6], v[3], v[4], v[5]));
        assert!(q.angle_to(&pose().rotation) < 1e-8);
        assert!(text.ends_with("--frame-id base_link --child-frame-id part\n"));
    }

    #[test]
    fn names_are_escaped_for_xml_and_the_shell() {
        let rows = [];
        let odd = PoseExport {
            base_frame: "base <1> & 'x'",
            ..export(&rows)
        };
        let urdf = render(ExportFormat::Urdf, &odd).unwrap();
        assert!(urdf.contains("<link name=\"base &lt;1&gt; &amp; &apos;x&apos;\"/>"));
        let tf = render(ExportFormat::RosTf, &odd).unwrap();
        assert!(tf.contains(r"--frame-id 'base <1> & '\''x'\''' "), "{tf}");
    }

    #[test]
    fn csv_quotes_ids_and_needs_touches() {
        let rows = [ExportRow {
            id: "a,\"b\"".to_owned(),
            ball_centre_m: [0.1, 0.2, 0.3],
            residual_m: -0.0001,
        }];
        let text = render(ExportFormat::Csv, &export(&rows)).unwrap();
        assert_eq!(
            text,
            "id,x_m,y_m,z_m,residual_m\n\"a,\"\"b\"\"\",0.100000000,0.200000000,0.300000000,-0.000100000\n"
        );
        assert!(render(ExportFormat::Csv, &export(&[])).is_err());
    }

    #[test]
    fn formats_parse_from_their_names_and_refuse_others() {
        for format in ExportFormat::ALL {
            assert_eq!(format.name().parse::<ExportFormat>(), Ok(format));
        }
        let error = "step".parse::<ExportFormat>().unwrap_err();
        assert!(error.contains("urdf, sdf, ros-tf, kuka-base, ur-pose, csv"));
    }

    #[test]
    fn a_pose_that_is_not_finite_is_refused() {
        let mut bad = export(&[]);
        bad.base_from_part.translation.vector.x = f64::NAN;
        assert!(render(ExportFormat::Urdf, &bad).is_err());
    }
}
