//! `robot-model`: check a URDF by printing, as JSON, what the library computes
//! from it at a given configuration: every frame's pose, a frame's Jacobian,
//! the mass matrix, gravity, nonlinear effects and RNEA torques.

use anyhow::{Context, Result, bail};
use clap::Parser;
use nalgebra::{DMatrix, Matrix6xX};
use robot_model::{
    FrameKind, JointKind, LoadOptions, MissingLimits, Model, Reference, Shape, crba,
    forward_kinematics, frame_jacobian, frame_placement, gravity, nonlinear_effects, rnea,
};
use serde_json::{Value, json};
use std::path::PathBuf;

/// Print kinematics and dynamics of a URDF robot at a configuration, as JSON.
#[derive(Parser, Debug)]
#[command(name = "robot-model", version)]
struct Args {
    /// The URDF file (any serial arm or tree with revolute, continuous,
    /// prismatic and fixed joints).
    urdf: PathBuf,
    /// Joint positions, comma- or space-separated, in joint order (see the
    /// "joints" output). Default: all zeros.
    #[arg(long, allow_hyphen_values = true)]
    q: Option<String>,
    /// Joint velocities. Default: zeros.
    #[arg(long, allow_hyphen_values = true)]
    v: Option<String>,
    /// Joint accelerations for RNEA. Default: zeros.
    #[arg(long, allow_hyphen_values = true)]
    a: Option<String>,
    /// Frame whose Jacobian is printed. Default: the last link.
    #[arg(long)]
    frame: Option<String>,
    /// Jacobian reference: "base" (origin velocity, base axes) or "local".
    #[arg(long, default_value = "base")]
    reference: String,
    /// Accept revolute/prismatic joints without <limit> as unlimited
    /// instead of rejecting the file.
    #[arg(long)]
    allow_missing_limits: bool,
}

fn parse_vector(name: &str, text: Option<&str>, n: usize) -> Result<Vec<f64>> {
    let Some(text) = text else {
        return Ok(vec![0.0; n]);
    };
    let values = text
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<f64>()
                .with_context(|| format!("--{name}: '{s}' is not a number"))
        })
        .collect::<Result<Vec<f64>>>()?;
    if values.len() != n {
        bail!(
            "--{name} has {} values, the robot has {n} joints",
            values.len()
        );
    }
    if let Some(bad) = values.iter().find(|v| !v.is_finite()) {
        bail!("--{name}: {bad} is not finite");
    }
    Ok(values)
}

/// Infinite limits become JSON null (JSON has no infinity).
fn num(x: f64) -> Value {
    if x.is_finite() { json!(x) } else { Value::Null }
}

fn matrix_rows(m: &DMatrix<f64>) -> Value {
    Value::Array(
        m.row_iter()
            .map(|r| json!(r.iter().copied().collect::<Vec<_>>()))
            .collect(),
    )
}

fn main() -> Result<()> {
    let args = Args::parse();
    let options = LoadOptions {
        missing_limits: if args.allow_missing_limits {
            MissingLimits::Unlimited
        } else {
            MissingLimits::Reject
        },
    };
    let model = Model::from_urdf_file(&args.urdf, &options)?;
    let nv = model.nv();
    let q = parse_vector("q", args.q.as_deref(), nv)?;
    let v = parse_vector("v", args.v.as_deref(), nv)?;
    let a = parse_vector("a", args.a.as_deref(), nv)?;
    let reference = match args.reference.as_str() {
        "base" => Reference::Base,
        "local" => Reference::Local,
        other => bail!("--reference must be 'base' or 'local', not '{other}'"),
    };
    let frame_name = match &args.frame {
        Some(f) => f.clone(),
        None => model
            .frames
            .iter()
            .rev()
            .find(|f| f.kind == FrameKind::Link)
            .map(|f| f.name.clone())
            .context("the model has no link frame")?,
    };
    let frame_id = model.frame_id(&frame_name)?;

    let mut data = model.create_data();
    forward_kinematics(&model, &mut data, &q);
    let frames: Vec<Value> = model
        .frames
        .iter()
        .enumerate()
        .map(|(id, f)| {
            let pose = frame_placement(&model, &data, id);
            let r = pose.rotation.to_rotation_matrix();
            let rot: Vec<Vec<f64>> = (0..3).map(|i| (0..3).map(|j| r[(i, j)]).collect()).collect();
            json!({
                "name": f.name,
                "kind": format!("{:?}", f.kind).to_lowercase(),
                "translation": [pose.translation.x, pose.translation.y, pose.translation.z],
                "quaternion_xyzw": [pose.rotation.i, pose.rotation.j, pose.rotation.k, pose.rotation.w],
                "rotation": rot,
            })
        })
        .collect();
    let mut jac = Matrix6xX::zeros(nv);
    frame_jacobian(&model, &data, frame_id, reference, &mut jac);
    let jac_rows: Vec<Vec<f64>> = (0..6)
        .map(|i| jac.row(i).iter().copied().collect())
        .collect();

    let mass = matrix_rows(crba(&model, &mut data, &q));
    let g: Vec<f64> = gravity(&model, &mut data, &q).iter().copied().collect();
    let nle: Vec<f64> = nonlinear_effects(&model, &mut data, &q, &v)
        .iter()
        .copied()
        .collect();
    let tau: Vec<f64> = rnea(&model, &mut data, &q, &v, &a)
        .iter()
        .copied()
        .collect();

    let joints: Vec<Value> = model.joints[1..]
        .iter()
        .map(|j| {
            json!({
                "name": j.name,
                "type": match j.kind {
                    JointKind::Revolute => "revolute",
                    JointKind::Continuous => "continuous",
                    JointKind::Prismatic => "prismatic",
                    JointKind::Root => "root",
                },
                "parent": model.joints[j.parent].name,
                "child_link": j.child_link,
                "axis": [j.axis.x, j.axis.y, j.axis.z],
                "limits": {
                    "lower": num(j.limits.lower),
                    "upper": num(j.limits.upper),
                    "velocity": num(j.limits.velocity),
                    "effort": num(j.limits.effort),
                },
            })
        })
        .collect();
    let missing_meshes: Vec<&str> = model
        .geometries
        .iter()
        .filter_map(|g| match &g.shape {
            Shape::Mesh {
                filename,
                resolved: None,
                ..
            } => Some(filename.as_str()),
            _ => None,
        })
        .collect();

    let out = json!({
        "robot": model.name,
        "root_link": model.root_link,
        "nq": nv,
        "moving_mass_kg": model.moving_mass(),
        "joints": joints,
        "q": q, "v": v, "a": a,
        "frames": frames,
        "jacobian": {
            "frame": frame_name,
            "reference": args.reference,
            "rows_linear_then_angular": jac_rows,
        },
        "mass_matrix": mass,
        "gravity": g,
        "nonlinear_effects": nle,
        "rnea": tau,
        "meshes_not_found": missing_meshes,
    });
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}
