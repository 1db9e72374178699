//! A J1939 NAME in a configuration file (the controller's config, the simulator's machine file):
//! its fields by name, every one required, each checked against its width in `excavator.dbc`'s
//! `AddressClaimed` message.
//!
//! ```toml
//! [j1939.name]
//! identity_number = 1          # 21 bits: the unit's serial number
//! manufacturer_code = 0        # 11 bits
//! ecu_instance = 0             # 3 bits
//! function_instance = 0        # 5 bits
//! function = 130               # 8 bits
//! vehicle_system = 0           # 7 bits
//! vehicle_system_instance = 0  # 4 bits
//! industry_group = 3           # 3 bits: construction
//! arbitrary_address_capable = false  # the project's addresses are fixed
//! ```

use serde::{Deserialize, Serialize};

use crate::address_claim::{Name, NameFields};
use crate::dbc::{SignalDesc, address_claimed as ac};

/// A NAME as a config file spells it (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NameConfig {
    /// Serial number of the unit (21 bits).
    pub identity_number: u32,
    /// SAE-assigned manufacturer code (11 bits).
    pub manufacturer_code: u16,
    /// Which of several ECUs of one function (3 bits).
    pub ecu_instance: u8,
    /// Which of several instances of the function (5 bits).
    pub function_instance: u8,
    /// What the node does (8 bits).
    pub function: u8,
    /// The vehicle system it belongs to (7 bits).
    pub vehicle_system: u8,
    /// Which of several vehicle systems of that kind (4 bits).
    pub vehicle_system_instance: u8,
    /// Industry group (3 bits; 3 = construction equipment).
    pub industry_group: u8,
    /// Must be false: the project's nodes cannot move to another address after losing a claim.
    pub arbitrary_address_capable: bool,
}

/// A NAME field that does not fit its width, or a NAME the project's nodes cannot use.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field} = {value}: {rule}")]
pub struct NameConfigError {
    /// The key as the file spells it (`identity_number`).
    pub field: &'static str,
    /// The value given.
    pub value: u64,
    /// What it breaks.
    pub rule: String,
}

impl From<Name> for NameConfig {
    fn from(name: Name) -> Self {
        let f = name.fields();
        Self {
            identity_number: f.identity_number,
            manufacturer_code: f.manufacturer_code,
            ecu_instance: f.ecu_instance,
            function_instance: f.function_instance,
            function: f.function,
            vehicle_system: f.vehicle_system,
            vehicle_system_instance: f.vehicle_system_instance,
            industry_group: f.industry_group,
            arbitrary_address_capable: f.arbitrary_address_capable,
        }
    }
}

impl NameConfig {
    /// The NAME.
    ///
    /// # Errors
    /// [`NameConfigError`] naming the first field wider than its bits, or `arbitrary_address_capable`
    /// set (the project's addresses are fixed: a node that says otherwise would be expected to move).
    pub fn name(&self) -> Result<Name, NameConfigError> {
        let widths: [(&'static str, u64, &SignalDesc); 8] = [
            (
                "identity_number",
                u64::from(self.identity_number),
                &ac::IDENTITY_NUMBER,
            ),
            (
                "manufacturer_code",
                u64::from(self.manufacturer_code),
                &ac::MANUFACTURER_CODE,
            ),
            (
                "ecu_instance",
                u64::from(self.ecu_instance),
                &ac::ECU_INSTANCE,
            ),
            (
                "function_instance",
                u64::from(self.function_instance),
                &ac::FUNCTION_INSTANCE,
            ),
            ("function", u64::from(self.function), &ac::FUNCTION),
            (
                "vehicle_system",
                u64::from(self.vehicle_system),
                &ac::VEHICLE_SYSTEM,
            ),
            (
                "vehicle_system_instance",
                u64::from(self.vehicle_system_instance),
                &ac::VEHICLE_SYSTEM_INSTANCE,
            ),
            (
                "industry_group",
                u64::from(self.industry_group),
                &ac::INDUSTRY_GROUP,
            ),
        ];
        for (field, value, sig) in widths {
            let max = (1u64 << sig.len) - 1;
            if value > max {
                return Err(NameConfigError {
                    field,
                    value,
                    rule: format!("must fit {} bits (0 to {max})", sig.len),
                });
            }
        }
        if self.arbitrary_address_capable {
            return Err(NameConfigError {
                field: "arbitrary_address_capable",
                value: 1,
                rule: "must be false: the controller (0x27) and the gateway (0x80) have fixed \
                       addresses"
                    .to_owned(),
            });
        }
        let fields = NameFields {
            identity_number: self.identity_number,
            manufacturer_code: self.manufacturer_code,
            ecu_instance: self.ecu_instance,
            function_instance: self.function_instance,
            function: self.function,
            vehicle_system: self.vehicle_system,
            vehicle_system_instance: self.vehicle_system_instance,
            industry_group: self.industry_group,
            arbitrary_address_capable: false,
        };
        // Every field was checked against its width above.
        Name::from_fields(&fields).map_err(|e| NameConfigError {
            field: "name",
            value: 0,
            rule: e.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::address_claim::{CONTROLLER_NAME, GATEWAY_NAME};

    #[test]
    fn the_default_names_round_trip() {
        for name in [CONTROLLER_NAME, GATEWAY_NAME] {
            assert_eq!(NameConfig::from(name).name(), Ok(name));
        }
    }

    #[test]
    fn every_field_is_checked_against_its_width() {
        let ok = NameConfig::from(CONTROLLER_NAME);
        let cases: [(&str, NameConfig, u64, u32); 8] = [
            (
                "identity_number",
                NameConfig {
                    identity_number: 1 << 21,
                    ..ok
                },
                1 << 21,
                21,
            ),
            (
                "manufacturer_code",
                NameConfig {
                    manufacturer_code: 2048,
                    ..ok
                },
                2048,
                11,
            ),
            (
                "ecu_instance",
                NameConfig {
                    ecu_instance: 8,
                    ..ok
                },
                8,
                3,
            ),
            (
                "function_instance",
                NameConfig {
                    function_instance: 32,
                    ..ok
                },
                32,
                5,
            ),
            (
                "vehicle_system",
                NameConfig {
                    vehicle_system: 128,
                    ..ok
                },
                128,
                7,
            ),
            (
                "vehicle_system_instance",
                NameConfig {
                    vehicle_system_instance: 16,
                    ..ok
                },
                16,
                4,
            ),
            (
                "industry_group",
                NameConfig {
                    industry_group: 8,
                    ..ok
                },
                8,
                3,
            ),
            (
                "arbitrary_address_capable",
                NameConfig {
                    arbitrary_address_capable: true,
                    ..ok
                },
                1,
                1,
            ),
        ];
        for (field, config, value, bits) in cases {
            let err = config.name().expect_err(field);
            assert_eq!((err.field, err.value), (field, value), "{err}");
            if field != "arbitrary_address_capable" {
                assert!(err.to_string().contains(&format!("{bits} bits")), "{err}");
            }
        }
        // The widest values fit.
        let widest = NameConfig {
            identity_number: (1 << 21) - 1,
            manufacturer_code: 2047,
            ecu_instance: 7,
            function_instance: 31,
            function: 255,
            vehicle_system: 127,
            vehicle_system_instance: 15,
            industry_group: 7,
            arbitrary_address_capable: false,
        };
        assert_eq!(
            widest.name().map(Name::raw),
            Ok(0x7FFF_FFFF_FFFF_FFFF - (1 << 48))
        );
    }

    #[test]
    fn a_table_with_a_missing_or_unknown_field_is_refused() {
        let full = toml::to_string(&NameConfig::from(GATEWAY_NAME)).expect("serialises");
        assert_eq!(
            toml::from_str::<NameConfig>(&full).ok().map(|c| c.name()),
            Some(Ok(GATEWAY_NAME))
        );
        let missing = full.replace("function = 129\n", "");
        assert!(toml::from_str::<NameConfig>(&missing).is_err());
        let unknown = format!("{full}serial = 3\n");
        assert!(toml::from_str::<NameConfig>(&unknown).is_err());
    }
}
