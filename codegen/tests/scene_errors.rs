use std::path::Path;
use flexdyn_codegen::error::Source;
use flexdyn_codegen::model::Model;

fn show(text: &str) {
    match Model::from_source(&Source::new(Path::new("t.toml"), text.into())) {
        Ok(_) => println!("OK\n"),
        Err(e) => println!("{e}\n  {:?}\n", e),
    }
}

const HEAD: &str = "name = \"s\"\n[parameters]\nm = 1.0\nl = 0.5\nk = { value = 2.0, runtime = true }\n[[coordinates]]\nname = \"x\"\n[[coordinates]]\nname = \"y\"\n";

#[test]
fn probe() {
    show("name = \"s\"\nbogus = 1\n[[coordinates]]\nname = \"x\"\n");
    show(&format!("{HEAD}[[components]]\ntype = \"point_mass\"\nmasss = \"m\"\n"));
    show("name = \"s\"\n[[coordinates]]\nname = \"x\"\nrnage = [0, 1]\n");
    show("name = \"s\"\n[parameters]\nm = { value = 1.0, runtme = true }\n[[coordinates]]\nname = \"x\"\n");
    show("name = \"s\"\n[parameters]\nm = inf\n[[coordinates]]\nname = \"x\"\n");
    show("name = \"s\"\n[parameters]\nm = { value = nan }\n[[coordinates]]\nname = \"x\"\n");
    show(&format!("{HEAD}[[components]]\ntype = \"point_mass\"\nmass = true\nposition = [0,0,0]\n"));
    show(&format!("{HEAD}[[components]]\ntype = \"energy\"\npotential = \"\"\"\nm*zz\"\"\"\n"));
    show(&format!("{HEAD}[[components]]\ntype = \"energy\"\npotential = \"\\tm*zz\"\n"));
    show(&format!("{HEAD}[[components]]\ntype = \"energy\"\npotential = \"l*sin(x\"\n"));
    show(&format!("{HEAD}[[components]]\ntype = \"energy\"\npotential = \"l * * x\"\n"));
    show(&format!("{HEAD}[[components]]\ntype = \"energy\"\npotential = \"l x\"\n"));
    show(&format!("{HEAD}[[components]]\ntype = \"energy\"\npotential = \"x)\"\n"));
    show(&format!("{HEAD}[[components]]\ntype = \"energy\"\npotential = \"x^2\"\n"));
    show(&format!("{HEAD}[[components]]\ntype = \"energy\"\npotential = 'x + \"a\"'\n"));
    show(&format!("{HEAD}[[components]]\ntype = \"energy\"\npotential = 'x + é + zz'\n"));
    show(&format!("{HEAD}[[components]]\ntype = \"energy\"\npotential = 'x + \"é + zz'\n"));
}
