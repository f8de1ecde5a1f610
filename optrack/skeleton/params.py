"""Parameters of the skeleton stage (MDCA): the likelihood, the annealed particle filter,
the motion model, initialisation and loss. docs/skeleton.md explains each."""

from __future__ import annotations

from optrack.params import Param, Schema, register

__all__ = ["SKELETON_PARAMS"]

SKELETON_PARAMS = register(
    Schema(
        "skeleton",
        [
            # ---- likelihood (eq. 7-9)
            Param(
                "sigma",
                0.15,
                min=0.01,
                max=2.0,
                step=0.01,
                help="Standard deviation of the Gaussian on a point's scaled distance to its part "
                "(in part radii).",
            ),
            Param(
                "alpha",
                0.6,
                min=0.05,
                max=5.0,
                step=0.05,
                help="Data association threshold: a point farther than this (in part radii) from "
                "every part is clutter and costs alpha.",
            ),
            Param(
                "support_weight",
                0.1,
                min=0.0,
                max=10.0,
                step=0.05,
                help="Cost of an area of interest (a part's half near a joint) left without data, "
                "against the mean squared distance term.",
            ),
            Param(
                "support_fraction",
                0.25,
                min=0.0,
                max=1.0,
                step=0.05,
                help="Share of its surface's share of the cloud an area of interest must hold to "
                "count as supported.",
            ),
            # ---- annealed particle filter
            Param(
                "particles",
                2000,
                min=50,
                max=20000,
                step=50,
                help="Particles per partition of the annealed particle filter.",
            ),
            Param(
                "layers",
                3,
                min=1,
                max=20,
                step=1,
                help="Annealing layers per partition and frame.",
            ),
            Param(
                "survival_rate",
                0.5,
                min=0.05,
                max=0.95,
                step=0.05,
                help="Share of effective particles each annealing layer keeps (Deutscher's "
                "alpha); sets each layer's exponent.",
            ),
            Param(
                "estimate_survival",
                0.1,
                min=0.001,
                max=1.0,
                step=0.01,
                help="The estimate is the particles' weighted mean, with an exponent that keeps "
                "this share of them effective (the best few).",
            ),
            Param(
                "anneal_decay",
                0.6,
                min=0.1,
                max=1.0,
                step=0.05,
                help="Each annealing layer diffuses particles by this factor times the previous "
                "layer's spread.",
            ),
            Param(
                "threads",
                0,
                min=0,
                max=64,
                step=1,
                help="CPU threads the likelihood shares its particles among (0: auto, the "
                "cores no other process keeps busy; more helps only where cores are idle).",
            ),
            Param(
                "torso_points",
                250,
                min=10,
                max=100000,
                step=10,
                help="The torso (scored on the whole body) is scored on a random sample of this "
                "many of the person's points.",
            ),
            Param(
                "reach_margin",
                0.15,
                min=0.0,
                max=1.0,
                step=0.05,
                unit="m",
                help="A limb is scored on the points within its length plus this of its root joint.",
            ),
            Param(
                "limb_gate",
                0.35,
                min=0.05,
                max=3.0,
                step=0.05,
                unit="m",
                help="While tracking, a limb is scored on the points within this distance of "
                "its axis where it was last found, and those no part explains.",
            ),
            Param(
                "explained_skip",
                0.1,
                min=0.0,
                max=1.0,
                step=0.05,
                help="A limb skips points the parts already fixed explain this well (in part "
                "radii): it could not explain them better.",
            ),
            Param(
                "collision_weight",
                2.0,
                min=0.0,
                max=100.0,
                step=0.5,
                help="Cost (against the log-likelihood) of an arm's elbow, forearm or wrist "
                "inside the trunk or the head, per part radius beyond collision_margin "
                "(0: none).",
            ),
            Param(
                "collision_margin",
                0.0,
                min=0.0,
                max=1.0,
                step=0.05,
                help="How far inside the trunk or the head (in its radii) an arm may reach "
                "before it costs anything.",
            ),
            # ---- motion model: Gaussian random walk per frame, agility per joint group
            Param(
                "agility_root_m",
                1.5,
                min=0.01,
                max=10.0,
                step=0.05,
                unit="m/s",
                help="Random walk of the pelvis position: standard deviation per second.",
            ),
            Param(
                "agility_heading_rad",
                6.0,
                min=0.01,
                max=20.0,
                step=0.1,
                unit="rad/s",
                help="Random walk of the body's heading (its turn about the vertical).",
            ),
            Param(
                "agility_root_rad",
                3.0,
                min=0.01,
                max=20.0,
                step=0.1,
                unit="rad/s",
                help="Random walk of the body's lean (forward and sideways).",
            ),
            Param(
                "agility_torso_rad",
                3.0,
                min=0.01,
                max=20.0,
                step=0.1,
                unit="rad/s",
                help="Random walk of the spine and neck angles.",
            ),
            Param(
                "agility_arms_rad",
                4.0,
                min=0.01,
                max=40.0,
                step=0.1,
                unit="rad/s",
                help="Random walk of the shoulder and elbow angles.",
            ),
            Param(
                "agility_legs_rad",
                4.0,
                min=0.01,
                max=40.0,
                step=0.1,
                unit="rad/s",
                help="Random walk of the hip and knee angles.",
            ),
            Param(
                "momentum",
                0.8,
                min=0.0,
                max=1.0,
                step=0.05,
                help="Share of the root's last velocity (position and heading, smoothed over "
                "frames) the particles move by before the random walk (0: a pure random walk).",
            ),
            Param(
                "limb_momentum",
                0.0,
                min=0.0,
                max=1.0,
                step=0.05,
                help="Share of each limb angle's last velocity (smoothed over frames) the "
                "particles move by before the random walk (0: the limbs walk at random). "
                "Off by default: with three sensors it helps a little, with two it costs.",
            ),
            Param(
                "limb_search",
                0.0,
                min=0.0,
                max=10.0,
                step=0.1,
                help="A limb whose areas of interest held none of their points at the last frame "
                "diffuses 1 + this times its agility (in proportion to the support it lacks).",
            ),
            Param(
                "limb_lost_support",
                0.0,
                min=0.0,
                max=1.0,
                step=0.05,
                help="While tracking, a limb whose areas of interest hold under this share of "
                "their points is searched again as initialisation does (0: never).",
            ),
            Param(
                "limb_research_s",
                1.0,
                min=0.0,
                max=10.0,
                step=0.1,
                unit="s",
                help="For this long after the skeleton (re)initialises, one limb a frame, in "
                "turn, is searched again as initialisation does, kept where it explains the "
                "cloud better (0: never).",
            ),
            Param(
                "limb_research_margin",
                0.2,
                min=0.0,
                max=2.0,
                step=0.05,
                help="A limb searched again (limb_research_s, limb_lost_support) takes the "
                "new pose only where the data's log-likelihood (without the arms' collision "
                "prior) rises by more than this: a limb already found gains up to about "
                "0.13 by chance, on points it does not own; a misplaced one gains 0.3 and "
                "more. The same margin decides the legs exchanged, the body turned round "
                "in its first second, and an arm kept away from rest at the start.",
            ),
            Param(
                "arm_rest_frames",
                4,
                min=0,
                max=60,
                step=1,
                help="While tracking, every this many frames one arm, in turn, is tried "
                "hanging at rest, kept where the whole body is clearly likelier so and the "
                "data like it as well: an arm folded through the chest or along the head, "
                "where no sensor sees it, hangs again (0: never).",
            ),
            Param(
                "limb_check_s",
                0.0,
                min=0.0,
                max=30.0,
                step=0.1,
                unit="s",
                help="While tracking, each limb in turn is searched again about this often "
                "(a short search), kept where the whole body explains the cloud better "
                "(0: never; 0.5 helped three sensors and hurt two).",
            ),
            Param(
                "facing_speed",
                0.5,
                min=0.0,
                max=5.0,
                step=0.1,
                unit="m/s",
                help="A person moving faster than this for facing_frames frames, against where "
                "the skeleton faces, is initialised again facing the motion (0: never).",
            ),
            Param(
                "facing_frames",
                5,
                min=1,
                max=100,
                step=1,
                help="Frames in a row of moving against the skeleton's facing before it is "
                "initialised again facing the motion.",
            ),
            Param(
                "max_dt",
                0.2,
                min=0.01,
                max=2.0,
                step=0.01,
                unit="s",
                help="Longest gap between frames the motion model spans; a longer one counts as this.",
            ),
            # ---- initialisation and loss (§IV-D)
            Param(
                "init_layers",
                12,
                min=1,
                max=40,
                step=1,
                help="Annealing layers of each coarse-to-fine initialisation step.",
            ),
            Param(
                "min_points",
                60,
                min=1,
                max=10000,
                step=1,
                help="Fewer points than this for a person: no update (the frame counts as a miss).",
            ),
            Param(
                "track_fraction",
                0.7,
                min=0.0,
                max=1.0,
                step=0.05,
                help="Share of the cloud the estimate must explain (within alpha) to be tracking.",
            ),
            Param(
                "lost_fraction",
                0.45,
                min=0.0,
                max=1.0,
                step=0.05,
                help="Below this share explained (the likelihood collapsed), a frame is a miss.",
            ),
            Param(
                "shape_seconds",
                1.0,
                min=0.0,
                max=30.0,
                step=0.1,
                unit="s",
                help="A person whose body is not given has their limb lengths and radii estimated "
                "from this long of tracking, starting from their height (0: never).",
            ),
            Param(
                "shape_frames",
                3,
                min=1,
                max=20,
                step=1,
                help="Frames, spread over shape_seconds, the body's estimate fits (each costs about "
                "half a second, once per person).",
            ),
            Param(
                "shape_steps",
                1,
                min=1,
                max=1000,
                step=1,
                help="Steps of the body's estimate per update (each refits two partitions of one "
                "kept frame's pose to one candidate body, about a 300th of the estimate), so that "
                "no frame stalls.",
            ),
            Param(
                "lost_frames",
                5,
                min=1,
                max=1000,
                step=1,
                help="Consecutive misses after which the skeleton is lost and initialises again.",
            ),
        ],
        help="Whole-body skeleton tracking (MDCA): body model, likelihood, annealed particle filter.",
    )
)
