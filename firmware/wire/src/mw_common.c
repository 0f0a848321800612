/* mw_common.c — error names for logs. */
#include "mocap_wire/mw_common.h"

const char* mw_error_name(int error) {
    switch (error) {
        case MW_OK:
            return "MW_OK";
        case MW_ERR_ARGUMENT:
            return "MW_ERR_ARGUMENT";
        case MW_ERR_DLC:
            return "MW_ERR_DLC";
        case MW_ERR_ID:
            return "MW_ERR_ID";
        case MW_ERR_RANGE:
            return "MW_ERR_RANGE";
        case MW_ERR_SPACE:
            return "MW_ERR_SPACE";
        case MW_ERR_VERSION:
            return "MW_ERR_VERSION";
        case MW_ERR_LENGTH:
            return "MW_ERR_LENGTH";
        case MW_ERR_CRC:
            return "MW_ERR_CRC";
        case MW_ERR_RECORD:
            return "MW_ERR_RECORD";
        default:
            return "MW_ERR_?";
    }
}
