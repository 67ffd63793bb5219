mod capture;
mod core;
mod scenario_cli;
mod links;
