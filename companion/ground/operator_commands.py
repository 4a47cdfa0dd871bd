"""The landing commands a ground station may send the companion, and their MAVLink command numbers (the table is in
:mod:`companion.ground.command_channel`)."""

from __future__ import annotations

from companion.guidance.vocabulary import OperatorCommand as OperatorCommand  # the landing logic's word for them

MAV_COMP_ID_ONBOARD_COMPUTER = 191
MAV_CMD_DO_GO_AROUND = 191
MAV_CMD_USER_1 = 31010
MAV_CMD_USER_2 = 31011
MAV_CMD_USER_3 = 31012


COMMAND_OF_MAV_CMD = {
    MAV_CMD_DO_GO_AROUND: OperatorCommand.GO_AROUND,
    MAV_CMD_USER_1: OperatorCommand.REJECT_ZONE,
    MAV_CMD_USER_2: OperatorCommand.LAND_NOW,
    MAV_CMD_USER_3: OperatorCommand.NEXT_FALLBACK,
}
