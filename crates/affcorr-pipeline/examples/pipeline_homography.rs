//! The pipeline with every default on one image pair: the homography and what it came from, as
//! one line of JSON (full precision), so that other entry points can be compared with it.
//!
//! ```text
//! ORT_DYLIB_PATH=... cargo run --example pipeline_homography -- MODELS_DIR IMAGE_A IMAGE_B
//! ```

use affcorr_pipeline::{Geometry, Pipeline, PipelineError, init_ort};

fn main() -> Result<(), PipelineError> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [models, a, b] = args.as_slice() else {
        eprintln!("usage: pipeline_homography MODELS_DIR IMAGE_A IMAGE_B");
        std::process::exit(2);
    };
    init_ort(None)?;
    let pipeline = Pipeline::builder().models_dir(models).build()?;
    let h = pipeline.homography(
        a.as_str(),
        b.as_str(),
        &Geometry::Homography.default_options(),
    )?;
    let model: Vec<String> = (0..3)
        .flat_map(|r| (0..3).map(move |c| (r, c)))
        .map(|(r, c)| format!("{:e}", h.estimate.model[(r, c)]))
        .collect();
    // Rust prints the shortest digits that read back as the same f64.
    let corrs: Vec<String> = h
        .matches
        .corrs
        .iter()
        .map(|row| {
            let v: Vec<String> = row.iter().map(|x| format!("{x:e}")).collect();
            format!("[{}]", v.join(", "))
        })
        .collect();
    println!(
        "{{\"matcher\": \"{}\", \"num_inliers\": {}, \"H\": [{}], \"corrs\": [{}]}}",
        pipeline.matcher(),
        h.estimate.num_inliers,
        model.join(", "),
        corrs.join(", ")
    );
    Ok(())
}
