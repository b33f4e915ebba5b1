//! The `chladni` package's integration tests, one binary (linking once is most of a test
//! binary's cost): the command run as a user runs it, and the library crates through their
//! public API. `support` is the shared test support (example files, CLI runs, the emulated
//! controller, ELF and photo fixtures).

mod support;

mod agreement;
mod bulk;
mod calibrate_photos;
mod calibrate_speed;
mod cell_owner;
mod cell_soak;
mod cli_analyze;
mod cli_animate;
mod cli_data_out;
mod cli_demo;
mod cli_device;
mod cli_emulator;
mod cli_figures_svg;
mod cli_flash;
mod cli_goal;
mod cli_inputs;
mod cli_json_failures;
mod cli_locate;
mod cli_model_inputs;
mod cli_photo;
mod cli_physics;
mod cli_plan;
mod cli_rig;
mod cli_serve_http;
mod cli_serve_limits;
mod cli_serve_modbus;
mod cli_step_numbers;
mod cli_verify;
mod dxf_import;
mod dynamic_maps;
mod faces;
mod faces_together;
mod feed_plan;
mod goal_plan;
mod grid_plan;
mod margin_plan;
mod planner;
mod plate_drive;
mod qemu_socket;
mod rim_plan;
mod steer_loop;
mod svg_import;
mod whole_plate;
