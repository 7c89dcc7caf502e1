//! What every ROS 2 command (`ros2 ...`, `sim --ros2`) takes to start its node.

use anyhow::{Context, Result};
use bywire_ros::dds::{RosNode, RosOptions};

/// Where the node runs.
#[derive(clap::Args)]
pub struct NodeArgs {
    /// The DDS domain (ROS_DOMAIN_ID).
    #[arg(long, env = "ROS_DOMAIN_ID", default_value_t = 0, value_parser = clap::value_parser!(u16).range(0..=232))]
    domain_id: u16,
    /// The node's namespace.
    #[arg(long, default_value = "/")]
    namespace: String,
    /// The node's name (default: the command's usual one).
    #[arg(long)]
    node_name: Option<String>,
    /// Network interfaces (names or addresses) DDS uses; default: all.
    #[arg(long = "dds-interface", value_name = "IFACE")]
    dds_interfaces: Vec<String>,
}

impl NodeArgs {
    pub fn open(&self, default_name: &str) -> Result<RosNode> {
        let options = RosOptions {
            domain_id: self.domain_id,
            namespace: self.namespace.clone(),
            node_name: self
                .node_name
                .clone()
                .unwrap_or_else(|| default_name.to_string()),
            interfaces: self.dds_interfaces.clone(),
        };
        RosNode::open(&options).context("cannot start the ROS 2 node")
    }
}
