mod capture;
mod core;
mod docs_cli;
mod links;
mod scenario_cli;
