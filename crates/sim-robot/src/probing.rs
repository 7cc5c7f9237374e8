//! The simulator probes a scene it is told about and the alignment side is not: a part mesh at a
//! true pose, the real tool (which may differ from the declared one) and a part that may be
//! scaled. It plans 3-2-1 touches ([`align_core::trials::planning`]) and runs them as one joint
//! path: for each touch an approach pose, the contact, a dwell at rest in contact, and back out.
//! The control socket's status says which touch is in contact and whether the arm is at rest.
//! Moves between touches are joint-space blends with no collision check: a simulator only.

use align_core::geometry::Mesh;
use align_core::pose::isometry_from_xyz_rpy;
use align_core::trials::planning::{PlanOptions, plan_touches};
use protocol::DigitalInput;
use protocol::sim::{Contact, ProbePlan, ProbeRequest, ProbeStatus};

use crate::Shared;
use crate::motion::{Motion, Trajectory, Waypoint};

/// Joint speed of the moves between touches, rad/s (the largest joint move sets the time).
const TRAVEL_SPEED_RAD_S: f64 = 2.0;
const SHORTEST_MOVE_S: f64 = 0.2;
/// The last bit into contact and back out, s.
const CONTACT_MOVE_S: f64 = 0.25;

/// How far before and past the contact an on-the-fly touch moves at constant speed, m.
const PASS_THROUGH_M: f64 = 0.001;

/// Bisection steps for the time the ball leaves the surface: the retreat lasts
/// `CONTACT_MOVE_S`, so 40 halvings leave well under a nanosecond.
const RELEASE_BISECTIONS: usize = 40;

#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Schedule {
    pub(crate) contacts: Vec<Contact>,
    pub(crate) end_s: f64,
    /// The digital input the trigger probe is wired to.
    pub(crate) trigger_input: DigitalInput,
}

/// Joints `PASS_THROUGH_M` before and past the contact along the probe axis.
fn through_contact(
    shared: &Shared,
    touch: &align_core::trials::planning::TouchPlan,
    flange_from_tcp: &nalgebra::Isometry3<f64>,
) -> Result<(Vec<f64>, Vec<f64>), String> {
    let contact = shared.chain.forward_unchecked(&touch.q_contact) * flange_from_tcp;
    let probe_axis = contact.rotation * nalgebra::Vector3::z();
    let solve = |shift_m: f64| {
        let target = nalgebra::Translation3::from(probe_axis * shift_m) * contact;
        shared
            .chain
            .inverse(
                &(target * flange_from_tcp.inverse()),
                &touch.q_contact,
                &align_core::kinematics::IkOptions::default(),
            )
            .map(|solution| solution.q)
            .map_err(|error| format!("probe: cannot pass through a contact: {error}"))
    };
    Ok((solve(-PASS_THROUGH_M)?, solve(PASS_THROUGH_M)?))
}

impl Schedule {
    /// The status the control socket reports at `time_s`.
    pub(crate) fn report(&self, time_s: f64, at_rest: bool) -> ProbeStatus {
        let active = self
            .contacts
            .iter()
            .position(|contact| (contact.from_s..contact.until_s).contains(&time_s));
        ProbeStatus {
            active_touch: active,
            at_rest,
            done: time_s >= self.end_s,
            touches: self.contacts.len(),
        }
    }

    /// The controller's digital inputs at `time_s`: the trigger input is high from the moment
    /// the ball reaches the surface until it leaves it, exactly, whatever the controller's
    /// sample times; a controller sampling the input sees the edge between two samples.
    pub(crate) fn digital_inputs(&self, time_s: f64) -> u64 {
        let touching = self
            .contacts
            .iter()
            .any(|contact| (contact.at_s..contact.released_s).contains(&time_s));
        if touching {
            self.trigger_input.mask()
        } else {
            0
        }
    }
}

/// When an on-the-fly touch's ball leaves the surface again: on the retreat that starts
/// pressed `PASS_THROUGH_M` into the part at `pressed_s`, the first time its centre is back
/// behind the contact point along the probe axis (`contact`: the TCP at the contact, its z
/// axis pointing into the part). The depth falls monotonically on the retreat's blend.
fn released_s(
    shared: &Shared,
    motion: &Motion,
    flange_from_tcp: &nalgebra::Isometry3<f64>,
    contact: &nalgebra::Isometry3<f64>,
    pressed_s: f64,
) -> f64 {
    let axis = contact.rotation * nalgebra::Vector3::z();
    let depth_m = |time_s: f64| {
        let tcp = shared.chain.forward_unchecked(&motion.position(time_s)) * flange_from_tcp;
        (tcp.translation.vector - contact.translation.vector).dot(&axis)
    };
    let (mut pressed, mut free) = (pressed_s, pressed_s + CONTACT_MOVE_S);
    for _ in 0..RELEASE_BISECTIONS {
        let middle = 0.5 * (pressed + free);
        if depth_m(middle) >= 0.0 {
            pressed = middle;
        } else {
            free = middle;
        }
    }
    free
}

fn finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

/// Plans the touches and starts the path; returns the plan.
pub(crate) fn start(request: &ProbeRequest, shared: &Shared) -> Result<ProbePlan, String> {
    let numbers = [
        request.mesh_scale,
        request.tip_radius,
        request.part_scale,
        request.max_tilt_rad,
        request.dwell_s,
    ];
    if !finite(&numbers)
        || request.base_from_part.first_non_finite().is_some()
        || request.tcp.first_non_finite().is_some()
    {
        return Err("probe: every number must be finite".to_owned());
    }
    if request.mesh_scale <= 0.0 || request.part_scale <= 0.0 || request.tip_radius < 0.0 {
        return Err("probe: mesh_scale and part_scale must be > 0, tip_radius >= 0".to_owned());
    }
    if let Some(speeds) = &request.on_the_fly_speeds_m_s
        && (speeds.is_empty()
            || speeds
                .iter()
                .any(|v| !(v.is_finite() && *v > 0.0 && *v <= 0.005)))
    {
        return Err("probe: on_the_fly_speeds_m_s needs speeds within (0, 0.005] m/s".to_owned());
    }
    if !(0.0..=2.0).contains(&request.dwell_s) {
        return Err(format!(
            "probe: dwell_s {} is outside 0-2 s",
            request.dwell_s
        ));
    }
    let soup = align_core::io::read_mesh(&request.mesh, request.mesh_scale)
        .map_err(|error| format!("probe: {error}"))?;
    let mesh = Mesh::new(&soup.vertices, &soup.triangles)
        .map_err(|error| format!("probe: {}: {error}", request.mesh.display()))?;
    let base_from_part =
        isometry_from_xyz_rpy(request.base_from_part.xyz, request.base_from_part.rpy);
    let flange_from_tcp = isometry_from_xyz_rpy(request.tcp.xyz, request.tcp.rpy);
    let start_s = shared.now_s() + 0.05;
    let current = shared.motion_at(start_s);
    let plan = plan_touches(
        &mesh,
        &base_from_part,
        &shared.chain,
        &flange_from_tcp,
        request.tip_radius,
        request.part_scale,
        &current,
        &PlanOptions {
            touches: request.touches,
            max_tilt_rad: request.max_tilt_rad,
            vary_tilt: request.vary_tilt,
            ..PlanOptions::default()
        },
    )
    .map_err(|error| format!("probe: {error}"))?;
    // Planning took a while: the path starts from where the arm is now.
    let mut time_s = shared.now_s() + 0.05;
    let mut waypoints = vec![Waypoint {
        time_s,
        q: shared.motion_at(time_s),
        linear: false,
    }];
    let mut contacts = Vec::with_capacity(plan.len());
    // On-the-fly touches: which, and their TCP at the contact.
    let mut pressed_through = Vec::new();
    let mut push = |q: &[f64], duration_s: f64, linear: bool, waypoints: &mut Vec<Waypoint>| {
        time_s += duration_s;
        waypoints.push(Waypoint {
            time_s,
            q: q.to_vec(),
            linear,
        });
        time_s
    };
    for (index, touch) in plan.iter().enumerate() {
        let from = &waypoints[waypoints.len() - 1].q;
        let largest_move = from
            .iter()
            .zip(&touch.q_approach)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        push(
            &touch.q_approach,
            (largest_move / TRAVEL_SPEED_RAD_S).max(SHORTEST_MOVE_S),
            false,
            &mut waypoints,
        );
        match &request.on_the_fly_speeds_m_s {
            None => {
                let in_contact = push(&touch.q_contact, CONTACT_MOVE_S, false, &mut waypoints);
                let leaving = push(
                    &touch.q_contact,
                    request.dwell_s.max(0.01),
                    false,
                    &mut waypoints,
                );
                // The retreat starts at rest on the surface: the ball leaves it at once.
                contacts.push(Contact {
                    from_s: in_contact,
                    until_s: leaving,
                    at_s: in_contact,
                    released_s: leaving,
                });
                push(&touch.q_approach, CONTACT_MOVE_S, false, &mut waypoints);
            }
            Some(speeds) => {
                let speed = speeds[index % speeds.len()];
                let (before, after) = through_contact(shared, touch, &flange_from_tcp)?;
                let crossing_s = PASS_THROUGH_M / speed;
                let from_s = push(&before, CONTACT_MOVE_S, false, &mut waypoints);
                let at_s = push(&touch.q_contact, crossing_s, true, &mut waypoints);
                let until_s = push(&after, crossing_s, true, &mut waypoints);
                contacts.push(Contact {
                    from_s,
                    until_s,
                    at_s,
                    // Found once the whole path is known, below.
                    released_s: until_s,
                });
                pressed_through.push((
                    index,
                    shared.chain.forward_unchecked(&touch.q_contact) * flange_from_tcp,
                ));
                push(&touch.q_approach, CONTACT_MOVE_S, false, &mut waypoints);
            }
        }
    }
    let motion = Motion::Path { waypoints };
    motion.check(&shared.limits)?;
    for (index, contact) in pressed_through {
        let pressed_s = contacts[index].until_s;
        contacts[index].released_s =
            released_s(shared, &motion, &flange_from_tcp, &contact, pressed_s);
    }
    let end_s = time_s;
    shared.set_motion(motion);
    let reply = ProbePlan {
        contacts: contacts.clone(),
        end_s,
        tilts_rad: plan.iter().map(|t| t.tilt_rad).collect(),
        touches: plan.len(),
    };
    *shared.probe.lock().unwrap_or_else(|p| p.into_inner()) = Some(Schedule {
        contacts,
        end_s,
        trigger_input: request.trigger_input,
    });
    Ok(reply)
}
