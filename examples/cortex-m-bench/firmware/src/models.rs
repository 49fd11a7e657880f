// The checked-in generated modules, as an embedded user would include them:
// the f64 ones from generated/, the f32 ones (the same scenes generated with
// `--precision f32`) from f32/.
#[allow(dead_code)]
pub mod parallel_robot_rigid {
    include!("../../../../generated/parallel_robot_rigid.rs");
}
#[allow(dead_code)]
pub mod spin_up_beam {
    include!("../../../../generated/spin_up_beam.rs");
}
pub mod f32 {
    #[allow(dead_code)]
    pub mod parallel_robot_rigid {
        include!("f32/parallel_robot_rigid.rs");
    }
    #[allow(dead_code)]
    pub mod spin_up_beam {
        include!("f32/spin_up_beam.rs");
    }
}
