//! The fixed RGB-D camera: an exact ray caster over the collision geometry
//! (the shapes the physics uses, intersected analytically), and the
//! ground-truth optical flow between consecutive frames.
//!
//! Rays are only cast where a primitive can appear: each primitive's cover
//! (corners for polyhedra, end spheres for capsules and cylinders) is
//! projected to a screen rectangle, and only the pixels inside it test that
//! primitive. Ray directions are `(x, y, 1)` in the camera frame, so a hit's
//! ray parameter is its depth.
//!
//! Files: `geometry` (primitives and ray intersections), `scene` (poses and
//! the robot's primitives), `render` (the renderer and its frame), `message`
//! (the stack's camera message), `visual` (pictures for people). The camera
//! knows nothing of the world: the world hands it primitives and poses.

mod geometry;
mod message;
mod render;
mod scene;
mod visual;

pub use geometry::{BodyRef, Class, Geometry, Primitive};
pub use message::fill_message;
pub use render::{Camera, CameraFrame, CameraShot, FLOW_MASK_MIN_PX};
pub use scene::{BodyPoses, prism_geometry, robot_primitives};
pub use visual::{depth_to_gray, flow_colour, flow_to_rgb};
