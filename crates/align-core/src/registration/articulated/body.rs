//! A robot as surfaces that move with its joints: each link's surface assembled from its URDF
//! shapes (primitives tessellated, mesh files read), the joints that move it, and forward
//! kinematics of every link from the root pose and the joint values.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::geometry::shapes::{box_soup, capsule_soup, cylinder_soup, sphere_soup};
use crate::geometry::{DistanceGrid, Mesh};
use crate::io::{TriangleSoup, read_mesh};
use crate::kinematics::{Geometry, JointKind, RobotModel, Shape};

#[derive(Debug, thiserror::Error)]
pub enum BodyError {
    #[error(
        "joint '{joint}' is {kind}: only revolute, continuous, prismatic and fixed joints can be fitted"
    )]
    UnsupportedJoint { joint: String, kind: &'static str },
    #[error("joint '{joint}' mimics '{master}', which is not a revolute or prismatic joint")]
    BadMimic { joint: String, master: String },
    #[error("the robot has several root links ({roots}); one tree is needed")]
    SeveralRoots { roots: String },
    #[error("link '{link}': {reason}")]
    LinkSurface { link: String, reason: String },
    #[error("no link of robot '{robot}' has visual or collision geometry to fit")]
    NoGeometry { robot: String },
}

/// Cell and margin of the links' distance grids: the searches ask about bands up to
/// 18 mm (three 6 mm keypoint voxels), which a 30 mm margin answers from 5 mm cells.
const GRID_CELL_M: f64 = 0.005;
const GRID_MARGIN_M: f64 = 0.03;
/// A link bigger than this many grid samples (16 MB, a box of about 0.8 m x 0.8 m x 0.8 m)
/// gets no grid: its queries go to its mesh, slower but exact, rather than spend seconds and
/// memory on a grid (a gantry beam, a table modelled as a link).
const MAX_GRID_SAMPLES: usize = 4_000_000;

/// A joint as the fit moves it.
#[derive(Debug, Clone)]
pub(crate) struct BodyJoint {
    pub parent: usize,
    pub parent_from_joint: Isometry3<f64>,
    pub axis: Unit<Vector3<f64>>,
    pub prismatic: bool,
    /// The fitted parameter driving the joint, its multiplier and offset (1, 0 unless the joint
    /// mimics another); `None` for fixed joints.
    pub driver: Option<(usize, f64, f64)>,
}

/// One link: its surface in the link frame, if it has geometry.
#[derive(Debug, Clone)]
pub struct BodyLink {
    pub name: String,
    pub surface: Option<Mesh>,
    /// The surface's signed distance on a grid, for the searches' near/inside questions.
    pub(crate) grid: Option<DistanceGrid>,
    /// The joint whose child this link is (`None` for the root).
    pub(crate) parent_joint: Option<usize>,
}

/// A joint value the fit estimates: a revolute (rad) or prismatic (m) joint that mimics none.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyParameter {
    pub name: String,
    pub prismatic: bool,
    pub lower: f64,
    pub upper: f64,
}

#[derive(Debug, Clone)]
pub struct ArticulatedBody {
    pub robot: String,
    links: Vec<BodyLink>,
    joints: Vec<BodyJoint>,
    /// Links in an order where every parent comes before its children.
    order: Vec<usize>,
    parameters: Vec<BodyParameter>,
    /// For each link, the parameters that move it (ancestors), nearest last.
    movers: Vec<Vec<usize>>,
}

/// The frame of a moving joint in the world: where its axis passes and where it points.
#[derive(Debug, Clone, Copy)]
pub(crate) struct JointAxis {
    pub origin: Point3<f64>,
    pub axis: Vector3<f64>,
    pub prismatic: bool,
}

impl ArticulatedBody {
    /// The robot's links with their visual shapes (collision shapes where a link has no visual).
    /// Joint parameters are the moving joints that mimic none, in the URDF's order.
    pub fn from_model(model: &RobotModel) -> Result<Self, BodyError> {
        let mut parameters = Vec::new();
        let mut parameter_of_joint = vec![None; model.joints().len()];
        for (index, joint) in model.joints().iter().enumerate() {
            match joint.kind {
                JointKind::Fixed => {}
                JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic => {
                    if joint.mimic.is_none() {
                        parameter_of_joint[index] = Some(parameters.len());
                        parameters.push(BodyParameter {
                            name: joint.name.clone(),
                            prismatic: joint.kind == JointKind::Prismatic,
                            lower: joint.limits.lower,
                            upper: joint.limits.upper,
                        });
                    }
                }
                kind => {
                    return Err(BodyError::UnsupportedJoint {
                        joint: joint.name.clone(),
                        kind: kind.name(),
                    });
                }
            }
        }
        let mut joints = Vec::with_capacity(model.joints().len());
        for (index, joint) in model.joints().iter().enumerate() {
            let driver = match (&joint.mimic, joint.kind) {
                (_, JointKind::Fixed) => None,
                (None, _) => parameter_of_joint[index].map(|p| (p, 1.0, 0.0)),
                (Some(mimic), _) => {
                    let master = model
                        .joints()
                        .iter()
                        .position(|j| j.name == mimic.joint)
                        .and_then(|m| parameter_of_joint[m])
                        .ok_or_else(|| BodyError::BadMimic {
                            joint: joint.name.clone(),
                            master: mimic.joint.clone(),
                        })?;
                    Some((master, mimic.multiplier, mimic.offset))
                }
            };
            joints.push(BodyJoint {
                parent: joint.parent,
                parent_from_joint: joint.parent_from_joint,
                axis: joint.axis,
                prismatic: joint.kind == JointKind::Prismatic,
                driver,
            });
        }
        let mut links = Vec::with_capacity(model.links().len());
        for (index, link) in model.links().iter().enumerate() {
            let shapes = if link.visuals.is_empty() {
                &link.collisions
            } else {
                &link.visuals
            };
            let surface = link_surface(shapes).map_err(|reason| BodyError::LinkSurface {
                link: link.name.clone(),
                reason,
            })?;
            let parent_joint = model.joints().iter().position(|joint| joint.child == index);
            let grid = surface
                .as_ref()
                .filter(|mesh| {
                    DistanceGrid::sample_count(mesh, GRID_CELL_M, GRID_MARGIN_M) <= MAX_GRID_SAMPLES
                })
                .map(|mesh| DistanceGrid::new(mesh, GRID_CELL_M, GRID_MARGIN_M));
            links.push(BodyLink {
                name: link.name.clone(),
                surface,
                grid,
                parent_joint,
            });
        }
        let roots: Vec<usize> = (0..links.len())
            .filter(|&l| links[l].parent_joint.is_none())
            .collect();
        if roots.len() != 1 {
            return Err(BodyError::SeveralRoots {
                roots: roots
                    .iter()
                    .map(|&l| format!("'{}'", links[l].name))
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        }
        if links.iter().all(|link| link.surface.is_none()) {
            return Err(BodyError::NoGeometry {
                robot: model.name.clone(),
            });
        }
        let mut order = roots;
        let mut next = 0;
        while next < order.len() {
            let parent = order[next];
            for (joint_index, joint) in model.joints().iter().enumerate() {
                if joint.parent == parent {
                    debug_assert_eq!(links[joint.child].parent_joint, Some(joint_index));
                    order.push(joint.child);
                }
            }
            next += 1;
        }
        let mut movers = vec![Vec::new(); links.len()];
        for &link in &order {
            if let Some(joint) = links[link].parent_joint {
                let mut moved_by = movers[joints[joint].parent].clone();
                if let Some((parameter, _, _)) = joints[joint].driver
                    && !moved_by.contains(&parameter)
                {
                    moved_by.push(parameter);
                }
                movers[link] = moved_by;
            }
        }
        Ok(Self {
            robot: model.name.clone(),
            links,
            joints,
            order,
            parameters,
            movers,
        })
    }

    pub fn links(&self) -> &[BodyLink] {
        &self.links
    }

    /// The same body with no distance grids: every query goes to the meshes.
    #[cfg(test)]
    pub(crate) fn without_grids(&self) -> Self {
        let mut body = self.clone();
        for link in &mut body.links {
            link.grid = None;
        }
        body
    }

    pub fn parameters(&self) -> &[BodyParameter] {
        &self.parameters
    }

    /// Each parameter at 0, or at the limit nearest 0: a pose every joint can take, for a robot
    /// with no home of its own.
    pub fn values_nearest_zero(&self) -> Vec<f64> {
        self.parameters
            .iter()
            .map(|p| 0.0f64.clamp(p.lower, p.upper))
            .collect()
    }

    /// Why `values` are not one value per parameter, each within its joint's limits (a message
    /// naming the joints, for the option or message that gave them); `Ok` when they are.
    pub fn check_values(&self, values: &[f64]) -> Result<(), String> {
        if values.len() != self.parameters.len() {
            return Err(format!(
                "{} values for the {} moving joints of '{}' ({})",
                values.len(),
                self.parameters.len(),
                self.robot,
                self.parameters
                    .iter()
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        match values
            .iter()
            .zip(&self.parameters)
            .find(|(value, p)| !(p.lower..=p.upper).contains(*value))
        {
            Some((value, p)) => Err(format!(
                "{value} for joint '{}' is outside its limits [{}, {}]",
                p.name, p.lower, p.upper
            )),
            None => Ok(()),
        }
    }

    pub fn root(&self) -> usize {
        self.order[0]
    }

    /// Links, parents before children.
    pub fn order(&self) -> &[usize] {
        &self.order
    }

    /// The parameters that move `link`.
    pub fn movers(&self, link: usize) -> &[usize] {
        &self.movers[link]
    }

    /// The links `parameter` moves.
    pub fn moved_by(&self, parameter: usize) -> Vec<usize> {
        (0..self.links.len())
            .filter(|&link| self.movers[link].contains(&parameter))
            .collect()
    }

    fn joint_value(&self, joint: &BodyJoint, q: &[f64]) -> f64 {
        joint
            .driver
            .map_or(0.0, |(p, multiplier, offset)| multiplier * q[p] + offset)
    }

    /// `world_from_link` of every link (indexed as the URDF's links).
    pub fn link_poses(&self, world_from_root: &Isometry3<f64>, q: &[f64]) -> Vec<Isometry3<f64>> {
        let mut poses = vec![Isometry3::identity(); self.links.len()];
        for &link in &self.order {
            poses[link] = match self.links[link].parent_joint {
                None => *world_from_root,
                Some(j) => {
                    let joint = &self.joints[j];
                    let value = self.joint_value(joint, q);
                    let motion = if joint.prismatic {
                        Isometry3::from_parts(
                            Translation3::from(joint.axis.into_inner() * value),
                            UnitQuaternion::identity(),
                        )
                    } else {
                        Isometry3::from_parts(
                            Translation3::identity(),
                            UnitQuaternion::from_axis_angle(&joint.axis, value),
                        )
                    };
                    poses[joint.parent] * joint.parent_from_joint * motion
                }
            };
        }
        poses
    }

    /// World axes of the joints driving each parameter's motion of `link`, with their
    /// multipliers: d(point on link)/d(q_p) = sum of multiplier * (axis x (point - origin)).
    pub(crate) fn axes(&self, poses: &[Isometry3<f64>]) -> Vec<Option<(JointAxis, usize, f64)>> {
        self.joints
            .iter()
            .map(|joint| {
                let (parameter, multiplier, _) = joint.driver?;
                let world_from_joint = poses[joint.parent] * joint.parent_from_joint;
                Some((
                    JointAxis {
                        origin: world_from_joint * Point3::origin(),
                        axis: world_from_joint.rotation * joint.axis.into_inner(),
                        prismatic: joint.prismatic,
                    },
                    parameter,
                    multiplier,
                ))
            })
            .collect()
    }

    /// The joints between the root and `link`, nearest the root first.
    pub(crate) fn joints_above(&self, link: usize) -> Vec<usize> {
        let mut path = Vec::new();
        let mut current = link;
        while let Some(joint) = self.links[current].parent_joint {
            path.push(joint);
            current = self.joints[joint].parent;
        }
        path.reverse();
        path
    }

    /// A bound on how far any link surface gets from the root frame's origin, whatever the
    /// joints (prismatic joints at their limits), m.
    pub fn max_reach_m(&self) -> f64 {
        let offsets: f64 = self
            .joints
            .iter()
            .map(|joint| {
                let travel = match joint.driver {
                    Some((p, multiplier, offset)) if joint.prismatic => {
                        let info = &self.parameters[p];
                        (multiplier * info.lower + offset)
                            .abs()
                            .max((multiplier * info.upper + offset).abs())
                    }
                    _ => 0.0,
                };
                joint.parent_from_joint.translation.vector.norm() + travel.min(1e3)
            })
            .sum();
        let largest_link = self
            .links
            .iter()
            .filter_map(|link| link.surface.as_ref())
            .map(|mesh| mesh.centroid().coords.norm() + mesh.radius_m())
            .fold(0.0, f64::max);
        offsets + largest_link
    }

    /// The whole robot at `q` as one mesh in the root frame (for the rigid first alignment).
    pub fn rigid_mesh(&self, q: &[f64]) -> Option<Mesh> {
        self.rigid_mesh_of(q, &(0..self.links.len()).collect::<Vec<_>>())
    }

    /// The links no joint moves (the base and what is bolted to it), as one mesh in the root
    /// frame.
    pub fn fixed_mesh(&self, q: &[f64]) -> Option<Mesh> {
        let fixed: Vec<usize> = (0..self.links.len())
            .filter(|&link| self.movers[link].is_empty())
            .collect();
        self.rigid_mesh_of(q, &fixed)
    }

    /// `links` at `q` as one mesh in the root frame.
    pub fn rigid_mesh_of(&self, q: &[f64], links: &[usize]) -> Option<Mesh> {
        let poses = self.link_poses(&Isometry3::identity(), q);
        let mut soup = TriangleSoup::default();
        for &link in links {
            if let Some(surface) = &self.links[link].surface {
                append(
                    &mut soup,
                    surface.vertices(),
                    surface.triangles(),
                    &poses[link],
                );
            }
        }
        Mesh::new(&soup.vertices, &soup.triangles).ok()
    }
}

fn append(
    soup: &mut TriangleSoup,
    vertices: impl Iterator<Item = Point3<f64>>,
    triangles: &[[u32; 3]],
    pose: &Isometry3<f64>,
) {
    let first = soup.vertices.len() as u32;
    soup.vertices.extend(vertices.map(|v| pose * v));
    soup.triangles
        .extend(triangles.iter().map(|t| t.map(|i| i + first)));
}

/// The union of a link's shapes as one mesh in the link frame; `None` without shapes.
fn link_surface(shapes: &[Shape]) -> Result<Option<Mesh>, String> {
    if shapes.is_empty() {
        return Ok(None);
    }
    let mut soup = TriangleSoup::default();
    for shape in shapes {
        let part = match &shape.geometry {
            Geometry::Box { size_m } => box_soup(*size_m),
            Geometry::Cylinder { radius_m, length_m } => cylinder_soup(*radius_m, *length_m),
            Geometry::Capsule { radius_m, length_m } => capsule_soup(*radius_m, *length_m),
            Geometry::Sphere { radius_m } => sphere_soup(*radius_m),
            Geometry::Mesh {
                uri,
                scale,
                resolved,
            } => {
                let path = resolved
                    .as_ref()
                    .map_err(|reason| format!("mesh '{uri}': {reason}"))?;
                let mut soup = read_mesh(path, 1.0).map_err(|error| error.to_string())?;
                for vertex in &mut soup.vertices {
                    for axis in 0..3 {
                        vertex[axis] *= scale[axis];
                    }
                }
                if scale.iter().product::<f64>() < 0.0 {
                    // A mirroring scale turns the triangles inside out.
                    for triangle in &mut soup.triangles {
                        triangle.swap(1, 2);
                    }
                }
                soup
            }
        };
        append(
            &mut soup,
            part.vertices.into_iter(),
            &part.triangles,
            &shape.link_from_shape,
        );
    }
    Mesh::new(&soup.vertices, &soup.triangles)
        .map(Some)
        .map_err(|error| format!("its geometry gives no usable surface: {error}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robots::ShippedRobot;

    #[test]
    fn shipped_robots_have_a_surface_per_moving_link_and_fk_matches_the_chain() {
        for robot in ShippedRobot::ALL {
            let model = robot.model().unwrap();
            let body = ArticulatedBody::from_model(&model).unwrap();
            let chain = robot.chain().unwrap();
            assert_eq!(body.parameters().len(), chain.dof());
            let q = robot.home();
            let base = model.link_id(robot.base_link()).unwrap();
            let flange = model.link_id(robot.flange_link()).unwrap();
            let poses = body.link_poses(&Isometry3::identity(), &q);
            let expected = poses[base].inverse() * poses[flange];
            let from_chain = chain.forward(&q).unwrap();
            assert!(
                (expected.translation.vector - from_chain.translation.vector).norm() < 1e-12,
                "{}",
                robot.name()
            );
            for link in body.links() {
                if let Some(surface) = &link.surface {
                    assert!(surface.num_triangles() > 0);
                }
            }
        }
    }

    #[test]
    fn joint_values_are_checked_for_count_and_limits_and_a_neutral_pose_is_within_them() {
        let urdf = r#"<robot name="slide">
            <link name="beam"><visual><geometry><box size="1 0.1 0.1"/></geometry></visual></link>
            <link name="carriage"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>
            <joint name="travel" type="prismatic"><parent link="beam"/><child link="carriage"/>
              <axis xyz="1 0 0"/><limit lower="0.1" upper="0.4" effort="1" velocity="1"/></joint>
        </robot>"#;
        let model = RobotModel::from_urdf_str(urdf, &Default::default()).unwrap();
        let body = ArticulatedBody::from_model(&model).unwrap();
        assert_eq!(body.values_nearest_zero(), [0.1]);
        assert_eq!(body.check_values(&[0.25]), Ok(()));
        let count = body.check_values(&[0.2, 0.3]).unwrap_err();
        assert!(
            count.contains("2 values for the 1 moving joints of 'slide' (travel)"),
            "{count}"
        );
        let outside = body.check_values(&[0.5]).unwrap_err();
        assert!(
            outside.contains("0.5 for joint 'travel' is outside its limits"),
            "{outside}"
        );
    }

    #[test]
    fn a_link_too_big_for_a_grid_keeps_its_mesh_only() {
        let urdf = r#"<robot name="gantry">
            <link name="beam"><visual><geometry><box size="6 0.3 0.3"/></geometry></visual></link>
            <link name="carriage"><visual><geometry><box size="0.2 0.2 0.1"/></geometry></visual></link>
            <joint name="travel" type="prismatic"><parent link="beam"/><child link="carriage"/>
              <origin xyz="0 0 0.2"/><axis xyz="1 0 0"/>
              <limit lower="-2.8" upper="2.8" effort="1" velocity="1"/></joint>
        </robot>"#;
        let model = RobotModel::from_urdf_str(urdf, &Default::default()).unwrap();
        let body = ArticulatedBody::from_model(&model).unwrap();
        assert!(body.links()[0].surface.is_some() && body.links()[0].grid.is_none());
        assert!(body.links()[1].grid.is_some());
    }

    #[test]
    fn a_planar_joint_is_refused_by_name() {
        let urdf = r#"<robot name="r">
            <link name="a"/><link name="b"/>
            <joint name="slide" type="planar"><parent link="a"/><child link="b"/></joint>
        </robot>"#;
        let model = RobotModel::from_urdf_str(urdf, &Default::default()).unwrap();
        let error = ArticulatedBody::from_model(&model).unwrap_err();
        assert!(error.to_string().contains("'slide' is planar"), "{error}");
    }
}
