//! Training: the schedule, loss, optimiser, initialisation hooks and the
//! loop that drives a [`crate::backend::TrainBackend`].

pub mod adam;
pub mod loss;
