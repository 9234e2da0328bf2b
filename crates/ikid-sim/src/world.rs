//! The rapier model of the forearm–hand system, built from the body model.
//!
//! Rapier has no reliable motorised 3-DoF multibody joint, so the wrist is three revolute
//! multibody joints in the body model's order, chained through two tiny links
//! ([`ikid::body::VIRTUAL_LINK`], which the reference dynamics include too). All joint axes
//! pass through the wrist centre; every link frame equals the forearm frame at zero angles.
//! Joint torques are applied as equal and opposite body torques on child and parent, which
//! is exactly a generalised force on that joint alone. Rapier's default joint damping is
//! removed: the only torques are the recorded ones and gravity.
//!
//! Rapier's public math is glam; conversion to nalgebra happens here and nowhere else.

use ikid::body::{BodyModel, COORDINATES, GRAVITY, N_COORDINATES, SegmentParams, VIRTUAL_LINK};
use nalgebra::{Isometry3, Vector3};
use rapier3d::math::{Pose, Rotation, Vector};
use rapier3d::prelude::*;

/// The simulated arm: rapier's state plus the handles to read and drive it.
pub struct WristWorld {
    pipeline: PhysicsPipeline,
    params: IntegrationParameters,
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    ccd: CCDSolver,
    /// forearm, link 1, link 2, hand.
    links: [RigidBodyHandle; N_COORDINATES + 1],
    joints: [MultibodyJointHandle; N_COORDINATES],
    /// Joint axes in the lab at the current state (updated by `read_axes`).
    forearm: Isometry3<f64>,
}

fn vec(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x, v.y, v.z)
}

fn pose(iso: &Isometry3<f64>) -> Pose {
    let q = iso.rotation.quaternion();
    Pose::from_parts(vec(&iso.translation.vector), Rotation::from_xyzw(q.i, q.j, q.k, q.w))
}

fn mass_properties(p: &SegmentParams) -> MassProperties {
    MassProperties::new(
        Vector::new(p.com[0], p.com[1], p.com[2]),
        p.mass,
        Vector::new(p.inertia[0], p.inertia[1], p.inertia[2]),
    )
}

impl WristWorld {
    /// The arm of subject `body` with the forearm at `shoulder_flexion` (rad), stepped at `dt`
    /// seconds with `substeps` solver iterations per step, starting at rest at zero angles.
    pub fn new(body: &BodyModel, shoulder_flexion: f64, dt: f64, substeps: usize) -> Self {
        let forearm = body.forearm_pose(shoulder_flexion);
        let at_wrist = pose(&forearm);
        let mut bodies = RigidBodySet::new();
        let fixed = bodies.insert(RigidBodyBuilder::fixed().pose(at_wrist));
        let dynamic = |p: &SegmentParams| {
            RigidBodyBuilder::dynamic()
                .pose(at_wrist)
                .additional_mass_properties(mass_properties(p))
                .can_sleep(false)
                .build()
        };
        let link1 = bodies.insert(dynamic(&VIRTUAL_LINK));
        let link2 = bodies.insert(dynamic(&VIRTUAL_LINK));
        let hand = bodies.insert(dynamic(&body.hand));
        let links = [fixed, link1, link2, hand];
        let mut multibody_joints = MultibodyJointSet::new();
        let joints: [MultibodyJointHandle; N_COORDINATES] = std::array::from_fn(|i| {
            let a = COORDINATES[i].axis;
            let joint = RevoluteJointBuilder::new(Vector::new(a[0], a[1], a[2])).contacts_enabled(false);
            multibody_joints.insert(links[i], links[i + 1], joint, true).expect("a chain has no loops")
        });
        let (mb, _) = multibody_joints.get_mut(joints[0]).expect("just inserted");
        mb.damping_mut().fill(0.0);
        let params = IntegrationParameters { dt, num_solver_iterations: substeps, ..Default::default() };
        WristWorld {
            pipeline: PhysicsPipeline::new(),
            params,
            islands: IslandManager::new(),
            broad_phase: BroadPhaseBvh::new(),
            narrow_phase: NarrowPhase::new(),
            bodies,
            colliders: ColliderSet::new(),
            impulse_joints: ImpulseJointSet::new(),
            multibody_joints,
            ccd: CCDSolver::new(),
            links,
            joints,
            forearm,
        }
    }

    /// Joint angles and velocities `(q, q̇)` as rapier holds them.
    pub fn state(&self) -> ([f64; N_COORDINATES], [f64; N_COORDINATES]) {
        let mut q = [0.0; N_COORDINATES];
        let mut qd = [0.0; N_COORDINATES];
        for (i, handle) in self.joints.iter().enumerate() {
            let (mb, link_id) = self.multibody_joints.get(*handle).expect("joint exists");
            let link = mb.link(link_id).expect("link exists");
            // A revolute joint's free coordinate is the rotation about its (local x) axis.
            q[i] = link.joint().coords()[3];
            qd[i] = mb.joint_velocity(link)[0];
        }
        (q, qd)
    }

    /// The hand's pose in the lab.
    pub fn hand_pose(&self) -> Isometry3<f64> {
        let p = self.bodies[self.links[N_COORDINATES]].position();
        let t = p.translation;
        let r = p.rotation;
        Isometry3::from_parts(
            nalgebra::Translation3::new(t.x, t.y, t.z),
            nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(r.w, r.x, r.y, r.z)),
        )
    }

    /// Applies joint torques `tau` (N·m) for the next step and advances one step.
    pub fn step(&mut self, tau: &[f64; N_COORDINATES]) {
        for h in &self.links {
            self.bodies[*h].reset_torques(false);
        }
        for i in 0..N_COORDINATES {
            // The joint axis in the lab: the parent link's orientation applied to the axis.
            let parent = self.bodies[self.links[i]].rotation();
            let a = COORDINATES[i].axis;
            let axis = *parent * Vector::new(a[0], a[1], a[2]);
            self.bodies[self.links[i + 1]].add_torque(axis * tau[i], true);
            self.bodies[self.links[i]].add_torque(-axis * tau[i], true);
        }
        let g = Vector::new(GRAVITY[0], GRAVITY[1], GRAVITY[2]);
        self.pipeline.step(
            g,
            &self.params,
            &mut self.islands,
            &mut self.broad_phase,
            &mut self.narrow_phase,
            &mut self.bodies,
            &mut self.colliders,
            &mut self.impulse_joints,
            &mut self.multibody_joints,
            &mut self.ccd,
            &(),
            &(),
        );
    }

    /// The forearm's pose in the lab.
    pub fn forearm_pose(&self) -> &Isometry3<f64> {
        &self.forearm
    }
}
