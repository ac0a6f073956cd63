"""Campaigns as ROS 2 recordings: single MCAP files and rosbag2 directories."""

from robocal_uncertainty.bagio.campaign_mcap import CampaignRecorder, read_campaign, write_campaign

__all__ = ["CampaignRecorder", "read_campaign", "write_campaign"]
