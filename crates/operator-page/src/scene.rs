//! What the 3D twin draws, computed on the server from the session `ips serve` loaded (never
//! from a file the page names): the part's mesh in its own frame, its nominal pose, the robot's
//! joint frames and tool centre point from forward kinematics, and each inspection's ball centre.
//! Everything is in metres in the robot base frame.

use std::path::Path;

use align_core::kinematics::Chain;
use align_core::tool::Tool;
use align_service::BadInput;
use align_service::session::LoadedSession;
use serde::Serialize;

use crate::robot_shapes::{LinkPose, RobotShapes, ShapeDocument};

/// The part's mesh in the part frame, m: what `GET /api/scene` sends once.
#[derive(Debug, Clone, Serialize)]
pub struct PartMesh {
    /// `[x, y, z]` per vertex, m.
    pub vertices: Vec<[f32; 3]>,
    /// Vertex indices, three per triangle.
    pub triangles: Vec<[u32; 3]>,
}

/// `GET /api/scene`: the fixed part of the twin.
#[derive(Debug, Clone, Serialize)]
pub struct SceneDocument {
    pub base_frame: String,
    pub part: PartMesh,
    /// `base_from_part` at the nominal pose, m and rad (roll, pitch, yaw as URDF: Rz Ry Rx).
    pub nominal_pose: protocol::Pose,
    /// The ball's radius, m.
    pub tip_radius_m: f64,
    /// The robot's visual primitives, each in its link's frame (empty: draw the joint line).
    pub robot_shapes: Vec<ShapeDocument>,
}

/// The robot at one joint sample: a line through its joints to the flange, and the TCP.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RobotPose {
    /// Origins of each joint's frame and the flange, m.
    pub joints_m: Vec<[f64; 3]>,
    /// The ball centre (TCP), m.
    pub tcp_m: [f64; 3],
    /// The tool's axis (TCP z), unit vector.
    pub tool_axis: [f64; 3],
    /// The pose of each link that has shapes, base frame.
    pub links: Vec<LinkPose>,
}

/// The `robot` event.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LiveRobot {
    #[serde(flatten)]
    pub pose: RobotPose,
    /// The joints, rad.
    pub q: Vec<f64>,
    pub controller_time_s: f64,
}

/// A captured inspection where the twin draws it: where the service places its ball (`list`'s
/// `balls`: the kinematics in use, the session's joint corrections), in metres.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TouchPoint {
    pub id: String,
    /// The ball centre, m.
    pub ball_centre_m: [f64; 3],
    /// The tool's axis at the touch, unit vector: the approach line.
    pub approach: [f64; 3],
}

impl From<&protocol::BallPlace> for TouchPoint {
    fn from(ball: &protocol::BallPlace) -> Self {
        Self {
            id: ball.id.clone(),
            ball_centre_m: ball.centre_mm.map(|v| v * 1e-3),
            approach: ball.approach,
        }
    }
}

/// The session's robot, tool and part, loaded once when the page starts.
#[derive(Debug)]
pub struct Scene {
    chain: Chain,
    tool: Tool,
    robot: Option<RobotShapes>,
    document: SceneDocument,
}

fn triple(v: &nalgebra::Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

impl Scene {
    /// Loads the session file `ips serve` was started with.
    pub fn load(session: &Path) -> Result<Self, BadInput> {
        let loaded = LoadedSession::load(session)?;
        let Some(chain) = loaded.chain.clone() else {
            return Err(BadInput(format!(
                "session '{}' has no robot: the page's twin needs one",
                session.display()
            )));
        };
        let folder = session.parent().unwrap_or(Path::new("."));
        let robot = loaded
            .file
            .robot
            .as_ref()
            .and_then(|section| RobotShapes::load(section, folder, &chain.joint_names()));
        // f32 is plenty for drawing and halves the document.
        #[allow(clippy::cast_possible_truncation)]
        let vertices = loaded
            .mesh
            .vertices()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect();
        let document = SceneDocument {
            base_frame: loaded.base_frame().to_owned(),
            part: PartMesh {
                vertices,
                triangles: loaded.mesh.triangles().to_vec(),
            },
            nominal_pose: loaded.file.part.nominal_pose,
            tip_radius_m: loaded.tool.tip_radius_m,
            robot_shapes: robot
                .as_ref()
                .map(|robot| robot.shapes().to_vec())
                .unwrap_or_default(),
        };
        Ok(Self {
            chain,
            tool: loaded.tool,
            robot,
            document,
        })
    }

    pub fn document(&self) -> &SceneDocument {
        &self.document
    }

    /// The robot at joints `q`, or `None` when `q` does not fit the chain.
    pub fn robot_pose(&self, q: &[f64]) -> Option<RobotPose> {
        self.chain.check_joints(q).ok()?;
        let frames = self.chain.joint_frames_unchecked(q);
        let flange = frames.last()?;
        let tcp = self.tool.base_from_tcp(flange);
        Some(RobotPose {
            joints_m: frames
                .iter()
                .map(|f| triple(&f.translation.vector))
                .collect(),
            tcp_m: triple(&tcp.translation.vector),
            tool_axis: triple(&(tcp.rotation * nalgebra::Vector3::z())),
            links: self
                .robot
                .as_ref()
                .map(|robot| robot.link_poses(q))
                .unwrap_or_default(),
        })
    }
}
