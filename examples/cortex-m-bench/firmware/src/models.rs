// The checked-in generated modules, as an embedded user would include them.
#[allow(dead_code)]
pub mod parallel_robot_rigid {
    include!("../../../../generated/parallel_robot_rigid.rs");
}
#[allow(dead_code)]
pub mod spin_up_beam {
    include!("../../../../generated/spin_up_beam.rs");
}
