//! Scenes of any size for the tests.

/// The spatial serial chain of `benches/chain_scaling.py`: `n` rigid bodies
/// with full inertia tensors on revolute joints whose axes alternate z, y,
/// x, under gravity, one actuator per joint.
pub fn spatial_chain(n: usize) -> String {
    let mut out = vec![
        format!("name = \"chain{n}\""),
        format!("description = \"Spatial serial chain of {n} rigid bodies\""),
        "gravity = [0, 0, -9.81]".into(),
    ];
    for k in 0..n {
        out.push(format!(
            "[[coordinates]]\nname = \"q{k}\"\nrange = [-3.1, 3.1]\n\
             velocity_range = [-3.0, 3.0]\ninitial = {}",
            0.1 * ((k % 5) as f64 - 2.0)
        ));
    }
    for k in 0..n {
        let parent = match k {
            0 => "world".to_string(),
            _ => format!("link{}", k - 1),
        };
        let translation = if k == 0 {
            "[0, 0, 0]"
        } else {
            "[0.05, 0.02, 0.3]"
        };
        let axis = ["z", "y", "x"][k % 3];
        out.push(format!(
            "[[frames]]\nname = \"link{k}\"\nparent = \"{parent}\"\ntranslation = {translation}\n\
             rotation = [{{ axis = \"{axis}\", angle = \"q{k}\" }}]"
        ));
    }
    for k in 0..n {
        let m = 1.0 + 0.1 * (k % 4) as f64;
        // The moments cycle every 30 links: beyond 34 links a steady growth
        // would break the triangle inequality (no body has such an inertia).
        let j = (k % 30) as f64;
        let (ixx, iyy, izz) = (0.02 + 0.001 * j, 0.025, 0.012 + 0.0005 * j);
        let (ixy, ixz, iyz) = (0.001, -0.0007, 0.0004);
        out.push(format!(
            "[[components]]\nname = \"body{k}\"\ntype = \"rigid_body\"\nmass = {m}\n\
             frame = \"link{k}\"\nposition = [0.01, -0.015, 0.15]\n\
             inertia = [[{ixx}, {ixy}, {ixz}], [{ixy}, {iyy}, {iyz}], [{ixz}, {iyz}, {izz}]]"
        ));
    }
    for k in 0..n {
        out.push(format!(
            "[[actuators]]\nname = \"tau{k}\"\ncoordinate = \"q{k}\""
        ));
    }
    out.join("\n\n")
}

/// A hub turning about z (inertia 2 kg m^2 about it), driven by the actuator
/// `hub_torque`, carrying a 1 m aluminium rod (radius 1 cm) as a clamped-free
/// flexible link with `modes` modes (at most 60) on 20 elements, under
/// `gravity` (m/s^2, along -z).
pub fn hub_beam(modes: usize, gravity: f64) -> String {
    format!(
        "name = \"hub_beam\"\ndescription = \"A hub-driven clamped-free beam with {modes} modes\"\n\
         gravity = [0, 0, {}]\n\n\
         [[coordinates]]\nname = \"theta\"\nrange = [-3.2, 3.2]\nvelocity_range = [-10.0, 10.0]\n\n\
         [[frames]]\nname = \"hub\"\nrotation = [{{ axis = \"z\", angle = \"theta\" }}]\n\n\
         [[components]]\nname = \"hub_body\"\ntype = \"rigid_body\"\nmass = 1.0\nframe = \"hub\"\n\
         inertia = [[1, 0, 0], [0, 1, 0], [0, 0, 2]]\n\n\
         [[components]]\nname = \"beam\"\ntype = \"flexible_link\"\nframe = \"hub\"\nlength = 1.0\n\
         material = {{ youngs_modulus = 7.0e10, poisson = 0.33, density = 2700 }}\n\
         section = {{ radius = 0.01 }}\nelements = 20\nmodes = {modes}\nboundary = \"clamped_free\"\n\n\
         [[actuators]]\nname = \"hub_torque\"\ncoordinate = \"theta\"\n",
        -gravity
    )
}
