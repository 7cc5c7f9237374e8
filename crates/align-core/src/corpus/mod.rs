//! A touch corpus made another way than the simulator and planner of [`crate::trials`]: parts
//! built as CAD exports look (thousands of triangles, fillets, holes, thin walls, an open skin;
//! [`parts`]), touches drawn uniformly by area with the tilts people use by hand, side contacts
//! with the ball's equator and hand-guided noise ([`touches`]), robots written from the vendors'
//! published DH tables with other base conventions ([`robots`]), and joint-space sessions through
//! a "true" robot with effects the alignment is not told about ([`sessions`]), and real UR
//! factory calibrations as UR's ROS drivers publish them ([`calibrations`]).
//!
//! Nothing here shares code or assumptions with `trials::planning`, `trials::probing` or
//! `trials::parts`; `docs/touch-corpus.md` says how the data differ and where every number
//! comes from.

mod build;
pub mod calibrations;
pub mod parts;
pub mod robots;
pub mod sessions;
pub mod touches;

use crate::geometry::MeshError;
use crate::io::FileError;
use crate::kinematics::{KinematicsError, ModelError};

#[derive(Debug, thiserror::Error)]
pub enum CorpusError {
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error(transparent)]
    File(#[from] FileError),
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error(transparent)]
    Kinematics(#[from] KinematicsError),
    #[error(
        "found only {found} collision-free touches after {draws} draws: the part leaves no room for the probe"
    )]
    NoTouchableSurface { found: usize, draws: usize },
    #[error("invalid option: {0}")]
    BadOption(String),
}
