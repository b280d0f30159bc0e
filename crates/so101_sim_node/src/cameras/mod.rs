//! The camera topics of the rendered frames (so101_sim::cameras renders them).

pub mod publish;
