//! `rpkm-node`: one ROS 2 node of rpkm in a process of its own (`rpkm-node tcp_estimator
//! --params params.yaml --backend both`), the program `rpkm launch` starts. Everything is in
//! `rpkm_nodes::program`; this file names no other crate, so the binary links the node set
//! alone.

fn main() {
    rpkm_nodes::program::main();
}
