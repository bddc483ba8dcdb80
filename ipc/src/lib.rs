//! Concord over iceoryx2: the wire contract ([`wire`]), service names ([`services`]), the
//! shared monotonic clock ([`clock`]), iceoryx2 plumbing ([`iox`]), operating-system set-up
//! ([`system`]) and the fixed-rate core process ([`core_service`]).

pub mod clock;
pub mod core_service;
pub mod feed;
pub mod iox;
pub mod monitor;
pub mod services;
pub mod system;
pub mod wire;
