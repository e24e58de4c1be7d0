"""LeRobot policy plugin for actengine: `--policy.path FOLDER` runs an actengine .actb blob.

LeRobot's register_third_party_plugins() imports this package (its distribution name starts with
"lerobot_policy_"); importing it registers the policy type "actengine" (ActengineConfig). LeRobot's
factory then finds ActenginePolicy in the sibling module modeling_actengine by its naming rule.
A folder written by `act_convert --package FOLDER` holds the blob, config.json of type "actengine"
and the pre/post-processor files that make_pre_post_processors loads.
"""

from .configuration_actengine import ActengineConfig

__all__ = ["ActengineConfig"]
